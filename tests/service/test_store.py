"""Artifact stores: atomic replace semantics, listing, deletion and key safety, for the filesystem
backend and the S3 backend (boto3 against a local moto server)."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import boto3
import httpx
import pytest

from hgcore.store import ArtifactNotFoundError, ArtifactStore, FilesystemStore
from hgcore.store.s3 import S3Store
from service.redis_server import free_loopback_port


@pytest.fixture(scope="module")
def moto_endpoint() -> Iterator[str]:
    port = free_loopback_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    endpoint = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 30
    while True:
        try:
            httpx.get(endpoint, timeout=1)
            break
        except httpx.HTTPError:
            if time.monotonic() > deadline:
                process.kill()
                raise
            time.sleep(0.1)
    try:
        yield endpoint
    finally:
        process.terminate()
        process.wait(timeout=10)


@pytest.fixture(params=["filesystem", "s3"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> ArtifactStore:
    if request.param == "filesystem":
        return FilesystemStore(tmp_path / "artifacts")
    endpoint = request.getfixturevalue("moto_endpoint")
    credentials = {"aws_access_key_id": "test", "aws_secret_access_key": "test", "region_name": "us-east-1"}
    client = boto3.client("s3", endpoint_url=endpoint, **credentials)
    bucket = f"hgrender-{tmp_path.name.lower().replace('_', '-')[-40:]}"
    client.create_bucket(Bucket=bucket)
    return S3Store(bucket, prefix="deploy-a", client=client)


def test_put_get_list_delete(store: ArtifactStore, tmp_path: Path) -> None:
    store.ping()
    store.put_bytes("jobs/a/chunks/0.npz", b"first")
    store.put_bytes("jobs/a/chunks/0.npz", b"second attempt")  # a retried chunk replaces, never duplicates
    source = tmp_path / "image.exr"
    source.write_bytes(b"E" * 3_000_000)
    store.put_file("jobs/a/image.exr", source)
    store.put_bytes("jobs/ab/other.json", b"{}")
    listing = store.list("jobs/a/")
    assert [(i.key, i.size_bytes) for i in listing] == [
        ("jobs/a/chunks/0.npz", len(b"second attempt")),
        ("jobs/a/image.exr", 3_000_000),
    ]
    assert store.get_bytes("jobs/a/chunks/0.npz") == b"second attempt"
    store.get_file("jobs/a/image.exr", tmp_path / "copy.exr")
    assert (tmp_path / "copy.exr").read_bytes() == source.read_bytes()
    assert store.exists("jobs/a/image.exr") and not store.exists("jobs/a/missing")
    with pytest.raises(ArtifactNotFoundError):
        store.get_bytes("jobs/a/missing")
    assert store.delete_prefix("jobs/a/") == 2
    assert store.list("jobs/a/") == [] and [i.key for i in store.list("jobs/ab/")] == ["jobs/ab/other.json"]


@pytest.mark.parametrize("key", ["", "../etc/passwd", "jobs/../x", "/abs", "jobs//x", "jobs/a b"])
def test_unsafe_keys_are_rejected(store: ArtifactStore, key: str) -> None:
    with pytest.raises(ValueError, match=r"^key:"):
        store.put_bytes(key, b"x")


def test_filesystem_writes_are_atomic(tmp_path: Path) -> None:
    """A failed write leaves the previous object intact and no temporary file behind."""
    store = FilesystemStore(tmp_path)
    store.put_bytes("jobs/j/summary.json", b"old")

    class InjectedError(Exception):
        pass

    def failing_write(out: object) -> None:
        out.write(b"partial")  # type: ignore[attr-defined]
        raise InjectedError

    with pytest.raises(InjectedError):
        store._atomic_write("jobs/j/summary.json", failing_write)
    assert store.get_bytes("jobs/j/summary.json") == b"old"
    assert sorted(p.name for p in (tmp_path / "jobs" / "j").iterdir()) == ["summary.json"]
