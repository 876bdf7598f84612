"""The job record and its one owner: typed fields round-trip through Redis text, an undeclared field is
refused, no module but ``hgcore.jobs.lifecycle`` touches a job's keys, and a job lives through the
lifecycle (create, a chunk, the merge, finalize with manifest and digests; fail; cancel; remove) on a real
Redis and filesystem store, without workers."""

from __future__ import annotations

import ast
import hashlib
import json
import re
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import redis

from hgcore.artifacts.keys import manifest_key, worker_log_key
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.record import JobRecord, JobSteps, StepRecord
from hgcore.jobs.status import JobStatus
from hgcore.store.filesystem import FilesystemStore
from tests.support import REPO_ROOT

PRODUCTION_PACKAGES = ("hgcore", "schemas", "service", "worker", "hgrender")
JOB_KEYS = frozenset(
    {"job_key", "steps_key", "scene_document_key", "owner_index_key", "JOBS_INDEX", "JOBS_BY_STATE"}
)
"""The names of a job's Redis keys (``hgcore.jobs.keys``)."""
KEY_OWNERS = frozenset({"hgcore/jobs/keys.py", "hgcore/jobs/lifecycle.py"})
KEY_PREFIX = "hgrender:" + "job"
"""How every key of a job's (``job:<id>…``, ``jobs…``) begins; written out only in ``hgcore/jobs/keys.py``."""


def a_record(**fields: object) -> JobRecord:
    values: dict[str, object] = {
        "id": uuid.uuid4().hex,
        "owner": "alice",
        "status": JobStatus.QUEUED,
        "priority": "normal",
        "spp": 8,
        "seed": 3,
        "chunk_count": 2,
        "created_at": time.time(),
    }
    return JobRecord(**(values | fields))  # type: ignore[arg-type]


def test_every_field_round_trips_through_redis_text() -> None:
    record = a_record(
        name="nightly",
        width=16,
        height=None,
        target_rel_error=0.1,
        time_budget_s=None,
        started_at=1.0 / 3.0,
        error="chunk 0: boom",
        noise_target_outcome={"rounds": [{"spp": 4, "seconds": 0.5, "rel_error": 0.2}], "met": False},
    )
    text = record.to_hash()
    assert all(isinstance(value, str) for value in text.values())
    assert text["chunks"] == "2" and text["height"] == "" and text["status"] == "queued"
    assert JobRecord.from_hash(text) == record  # floats exactly (repr), enums, JSON, None
    assert record.noise_target is not None and record.noise_target.rel_error == 0.1
    steps = StepRecord.encode_step(1, status="running", progress=0.25, pid=42, spp=None)
    assert steps == {"1.status": "running", "1.progress": "0.25", "1.pid": "42", "1.spp": ""}
    parsed = JobSteps.from_hash(steps | {"merge.status": "running"}, chunk_count=2)
    assert parsed.chunks[1] == StepRecord(status="running", progress=0.25, pid=42)
    assert parsed.chunks[0] == StepRecord() and parsed.merge == StepRecord(status="running")


def test_a_field_the_record_does_not_declare_is_refused() -> None:
    with pytest.raises(KeyError, match="finshed_at"):
        JobRecord.encode_fields(finshed_at=1.0)
    with pytest.raises(KeyError, match="attempt"):
        StepRecord.encode_step(0, attempt=2)


def _names_used(tree: ast.Module) -> set[str]:
    names = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
    names |= {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)}
    names |= {
        alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) for alias in node.names
    }
    return names


def _job_key_literals(tree: ast.Module) -> list[str]:
    """The string literals (f-strings' text included) that spell out a job's Redis key, by line."""
    return [
        f"line {node.lineno}: a {KEY_PREFIX!r}… literal"
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and str(node.value).startswith(KEY_PREFIX)
    ]


def job_key_users(root: Path, folders: tuple[str, ...], *, names: bool = True) -> dict[str, list[str]]:
    """Modules under ``folders`` of ``root`` that write out a job's key (``"hgrender:job…"``) outside
    ``hgcore/jobs/keys.py`` or (``names``) name one (the ``hgcore.jobs.keys`` functions and constants)
    outside the owners."""
    users = {}
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            relative = path.relative_to(root).as_posix()
            tree = ast.parse(path.read_text(), filename=str(path))
            found = sorted(_names_used(tree) & JOB_KEYS) if names and relative not in KEY_OWNERS else []
            found += _job_key_literals(tree) if relative != "hgcore/jobs/keys.py" else []
            if found:
                users[relative] = found
    return users


def test_only_the_lifecycle_touches_a_jobs_keys() -> None:
    """A job's record, steps, scene and indexes are read and written by ``JobLifecycle`` alone; the API,
    the tasks, the worker class, the reconciler, regression evaluation and the benchmarks go through it,
    and nothing but ``hgcore.jobs.keys`` spells out a key."""
    assert job_key_users(REPO_ROOT, (*PRODUCTION_PACKAGES, "bench")) == {}


def test_tests_build_a_jobs_keys_with_the_key_functions() -> None:
    """Tests that break a job's state on purpose (lose its scene, its record) name the keys through
    ``hgcore.jobs.keys``, so that a renamed key cannot leave them deleting nothing."""
    assert job_key_users(REPO_ROOT, ("tests",), names=False) == {}


def test_a_key_spelled_out_or_named_outside_the_owner_is_found(tmp_path: Path) -> None:
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "raw.py").write_text(
        'def fields(client, job_id):\n    return client.hgetall(f"hgrender:job:{job_id}:chunks")\n'
    )
    (tmp_path / "bench" / "named.py").write_text("from hgcore.jobs.keys import JOBS_BY_STATE\n")
    (tmp_path / "bench" / "fine.py").write_text('TOKENS = "hgrender:token:*"\n')
    assert job_key_users(tmp_path, ("bench",)) == {
        "bench/named.py": ["JOBS_BY_STATE"],
        "bench/raw.py": ["line 2: a 'hgrender:job'… literal"],
    }


LIFECYCLE_SECTION = "## The job lifecycle (one line a module)"
JOBS_PACKAGE = frozenset({"hgcore/jobs/__init__.py"})


def lifecycle_picture(markdown: str) -> list[str]:
    """The lines of the code block in ``docs/architecture.md``'s job-lifecycle section."""
    section = markdown.split(LIFECYCLE_SECTION, 1)[1].split("\n## ", 1)[0]
    return section.split("```", 2)[1].strip("\n").splitlines()


def picture_problems(lines: list[str], root: Path) -> list[str]:
    """What is wrong with the picture: a line that does not begin with one module's path, a module with
    more than one line, a path it names that does not exist, a module of ``hgcore/jobs/`` left out."""
    problems = []
    modules = [line.split(maxsplit=1)[0] if line.strip() else "" for line in lines]
    for line, module in zip(lines, modules, strict=True):
        if not module.endswith(".py") or line.startswith(" "):
            problems.append(f"not a module's line: {line!r}")
    problems += [f"{m} has {modules.count(m)} lines" for m in sorted(set(modules)) if modules.count(m) > 1]
    named = set(re.findall(r"[\w./]+\.py\b", "\n".join(lines)))
    problems += [f"{path} does not exist" for path in sorted(named) if not (root / path).is_file()]
    jobs = {p.relative_to(root).as_posix() for p in (root / "hgcore" / "jobs").glob("*.py")}
    problems += [f"{path} is not in the picture" for path in sorted(jobs - set(modules) - JOBS_PACKAGE)]
    return problems


def test_the_architecture_docs_picture_every_lifecycle_module_once() -> None:
    lines = lifecycle_picture((REPO_ROOT / "docs" / "architecture.md").read_text())
    assert len(lines) >= 10
    assert picture_problems(lines, REPO_ROOT) == []


def test_a_wrong_lifecycle_picture_is_found(tmp_path: Path) -> None:
    (tmp_path / "hgcore" / "jobs").mkdir(parents=True)
    for name in ("__init__.py", "keys.py", "lifecycle.py", "status.py"):
        (tmp_path / "hgcore" / "jobs" / name).write_text("")
    lines = [
        "hgcore/jobs/lifecycle.py   the owner; keys in hgcore/jobs/keys.py",
        "                           a continuation line",
        "hgcore/jobs/lifecycle.py   a second line of the same module",
        "service/gone.py            renamed away",
    ]
    assert picture_problems(lines, tmp_path) == [
        "not a module's line: '                           a continuation line'",
        "hgcore/jobs/lifecycle.py has 2 lines",
        "service/gone.py does not exist",
        "hgcore/jobs/keys.py is not in the picture",
        "hgcore/jobs/status.py is not in the picture",
    ]


@pytest.fixture
def lifecycle(redis_url: str, tmp_path: Path) -> Iterator[JobLifecycle]:
    client = redis.Redis.from_url(redis_url)
    yield JobLifecycle(client, FilesystemStore(tmp_path / "store"))
    client.close()


def _create(lifecycle: JobLifecycle, record: JobRecord) -> None:
    with lifecycle.client.pipeline() as pipe:
        pipe.multi()
        lifecycle.add_to(pipe, record, {"film": {"spp": record.spp}})
        pipe.execute()


def test_a_job_succeeds_through_the_lifecycle(lifecycle: JobLifecycle, tmp_path: Path) -> None:
    record = a_record()
    _create(lifecycle, record)
    assert lifecycle.record(record.id) == record
    assert lifecycle.start_chunk(record.id, 0, "w1", 100, spp=4) == 1
    assert lifecycle.start_chunk(record.id, 0, "w2", 101, spp=4) == 2  # a retry: the next attempt
    assert lifecycle.status(record.id) == JobStatus.RUNNING
    lifecycle.report_progress(record.id, 0, 0.5)
    view = lifecycle.view(record.id)
    assert view is not None and view.progress == pytest.approx(0.25) and view.workers == ["w2"]
    lifecycle.finish_chunk(record.id, 0, samples=1024, seconds=0.5)
    lifecycle.finish_chunk(record.id, 1, samples=1024, seconds=0.5)
    merge_started_s = time.monotonic()
    lifecycle.start_merge(record.id, "w1", 102)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / "image.exr").write_bytes(b"not really an EXR")
    lifecycle.finalize(record.id, out_dir, {"spp": 8}, merge_started_s)
    view = lifecycle.view(record.id)
    assert view is not None and view.status == JobStatus.SUCCEEDED and view.progress == 1.0
    assert lifecycle.steps(record.id).completions() == {"0": 1, "1": 1, "merge": 1}
    manifest = json.loads(lifecycle.store.get_bytes(manifest_key(record.id)))
    assert manifest["job"]["status"] == "succeeded" and manifest["job"]["timings"]["total_s"] > 0
    digests = {a["name"]: a["sha256"] for a in manifest["artifacts"]}
    assert digests["image.exr"] == hashlib.sha256(b"not really an EXR").hexdigest()
    assert {"worker.log", "scene.json"} <= set(digests)
    lifecycle.fail(record.id, "too late")  # a final status never changes
    assert lifecycle.status(record.id) == JobStatus.SUCCEEDED
    lifecycle.remove(record.id)
    assert lifecycle.record(record.id) is None
    assert lifecycle.view(record.id) == view.model_copy(update={"eta_s": None})  # kept by the manifest


def test_a_job_fails_or_is_canceled_through_the_lifecycle(lifecycle: JobLifecycle, tmp_path: Path) -> None:
    failing, canceled = a_record(), a_record()
    _create(lifecycle, failing)
    _create(lifecycle, canceled)
    lifecycle.start_chunk(failing.id, 0, "w1", 100, spp=4)
    lifecycle.fail(failing.id, "chunk 0: RuntimeError: boom")
    view = lifecycle.view(failing.id)
    assert view is not None and (view.status, view.error) == (JobStatus.FAILED, "chunk 0: RuntimeError: boom")
    log = lifecycle.store.get_bytes(worker_log_key(failing.id)).decode()
    assert log.endswith("error: chunk 0: RuntimeError: boom\n")
    lifecycle.start_chunk(canceled.id, 1, "w1", 100, spp=4)
    assert lifecycle.cancel(canceled.id) and not lifecycle.cancel(canceled.id)
    lifecycle.close_unfinished_steps(canceled.id)
    assert [step.status for step in lifecycle.steps(canceled.id).chunks] == ["canceled", "canceled"]
    # A late round of a canceled job changes nothing: its record is written only while it runs.
    partial = tmp_path / "round.npz"
    partial.write_bytes(b"partial")
    assert not lifecycle.publish_round(canceled.id, partial, {"rounds": []})
    record = lifecycle.record(canceled.id)
    assert record is not None and record.noise_target_outcome is None
