"""Fixtures of the service tests: a live API (uvicorn in a thread) on the session's private Redis, queue
workers as real ``hgrender worker`` subprocesses, tokens, and tiny example scenes (16x16 px, 4 spp)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis
import uvicorn

from hgcore.settings import Settings
from hgrender.cli.service import worker_command_line
from hgrender.client import HgrenderClient
from schemas import EXAMPLES_DIR
from service.auth import TokenRegistry
from service.main import create_app
from service.redis_server import free_loopback_port

REPO_ROOT = Path(__file__).resolve().parents[2]


def tiny_scene(name: str = "cornell_box.json", size_px: int = 16, spp: int = 4) -> dict[str, Any]:
    """An example scene shrunk to ``size_px`` square and ``spp`` samples (fast on 2 cores)."""
    scene = json.loads((EXAMPLES_DIR / name).read_text())
    scene.setdefault("film", {}).update({"width": size_px, "height": size_px, "spp": spp})
    scene["film"]["bands"] = min(scene["film"].get("bands", 16), 8)
    return scene


def fast_settings(redis_url: str, data_dir: Path, **overrides: Any) -> Settings:
    """Settings whose failure detection runs in seconds: heartbeat TTL 1 + 3 s, maintenance every 2 s."""
    values: dict[str, Any] = {
        "redis_url": redis_url,
        "data_dir": data_dir,
        "worker_monitoring_interval_s": 1,
        "worker_heartbeat_grace_s": 3,
        "worker_maintenance_interval_s": 2,
        "chunk_retry_intervals_s": [1],
        "default_chunks": 2,
        "progress_interval_s": 0.1,
        "max_request_bytes": 2 * 1024 * 1024,
    }
    return Settings(**(values | overrides))


class _ThreadedServer(uvicorn.Server):
    def install_signal_handlers(self) -> None:  # the test process keeps its own handlers
        pass


@dataclass
class LiveService:
    """A running API plus helpers to start workers and make clients."""

    settings: Settings
    base_url: str
    admin_token: str
    redis: redis.Redis
    workers: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def client(self, token: str | None = None) -> HgrenderClient:
        return HgrenderClient(self.base_url, token=token if token is not None else self.admin_token)

    def token(self, owner: str, scopes: tuple[str, ...] = ("submit", "read")) -> str:
        secret, _ = TokenRegistry(self.redis).create(owner, scopes)
        return secret

    def start_worker(self, name: str | None = None, **env_overrides: str) -> subprocess.Popen[bytes]:
        """An ``hgrender worker`` subprocess in its own session (so a test can kill all of it)."""
        env = {**os.environ, **self.settings.to_env(), **env_overrides}
        command = worker_command_line(*(["--name", name] if name else []))
        log = (self.settings.data_dir / f"worker-{name or len(self.workers)}.log").open("wb")
        process = subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        self.workers.append(process)
        return process

    def stop_workers(self, timeout_s: float = 15.0) -> None:
        """Warm shutdown (SIGTERM: RQ releases its scheduler lock and registers its death), then
        SIGKILL of whatever is left in each worker's process group."""
        for process in self.workers:
            if process.poll() is None:
                process.terminate()
        for process in self.workers:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=timeout_s)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.pid, signal.SIGKILL)
            process.wait()
        self.workers.clear()


@pytest.fixture(scope="module")
def live_service(redis_url: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveService]:
    """API on a free loopback port over a flushed Redis; workers are started by the tests."""
    client = redis.Redis.from_url(redis_url)
    client.flushdb()
    settings = fast_settings(redis_url, tmp_path_factory.mktemp("service-data"))
    admin_token, _ = TokenRegistry(client).create("admin", ("admin",), "test admin")
    port = free_loopback_port()
    server = _ThreadedServer(
        uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    base_url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 20
    while not server.started:
        if time.monotonic() > deadline:
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.05)
    service = LiveService(settings, base_url, admin_token, client)
    try:
        yield service
    finally:
        service.stop_workers()
        server.should_exit = True
        thread.join(timeout=10)
        client.close()


def wait_for(predicate: Callable[[], Any], timeout_s: float, what: str, interval_s: float = 0.1) -> Any:
    """Poll ``predicate`` until it returns something truthy; fail the test after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval_s)
    pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


def http_get(service: LiveService, path: str, token: str | None = None) -> httpx.Response:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.get(service.base_url + path, headers=headers, timeout=30)


def parent_of(pid: int) -> int | None:
    """The parent pid of process ``pid`` (Linux /proc), None if it is gone."""
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return None


def children_of(pid: int) -> list[int]:
    """Pids of the live child processes of ``pid``."""
    return [
        int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit() and parent_of(int(p.name)) == pid
    ]


def describe_process(pid: int) -> str:
    """``pid``, its state, parent and command line (Linux /proc), for failure messages."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except (OSError, IndexError):
        return f"{pid} (gone)"
    return f"{pid} state {fields[0]} parent {fields[1]}: {command.strip()[:160]}"


def is_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
