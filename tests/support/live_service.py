"""The live service the tests run against: the real API (uvicorn in a thread of the test process) over a
real Redis, with real ``hgrender worker`` subprocesses started when a test needs them, tokens and
clients. ``tests/conftest.py``'s ``live_service`` fixture gives each test module a fresh one; this module
holds the class and the settings it runs with."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis
import uvicorn

from hgcore.artifacts.exr import ExrImage, read_exr
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.record import JobSteps
from hgcore.settings import Settings
from hgcore.store import store_from_settings
from hgrender.cli.service import worker_command_line
from hgrender.client import HgrenderClient
from service.auth import TokenRegistry, ensure_admin_token
from service.jobs import JobService
from service.main import create_app
from service.redis_server import free_loopback_port

FINAL_STATUSES = ("succeeded", "failed", "canceled")


@dataclass(frozen=True)
class RenderedJob:
    """A job that succeeded and its ``image.exr``, read back with OpenImageIO."""

    job_id: str
    exr: ExrImage


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
    """A running API (auth on, ``admin.token`` in its data dir as ``hgrender serve`` writes it) plus
    helpers to start workers, make clients and tokens, and render jobs."""

    settings: Settings
    base_url: str
    admin_token: str
    redis: redis.Redis
    workers: list[subprocess.Popen[bytes]] = field(default_factory=list)
    _admin: HgrenderClient | None = None

    @property
    def data_dir(self) -> Path:
        return self.settings.data_dir

    @property
    def token(self) -> str:
        """The admin token (what a user of ``hgrender serve`` reads from ``admin.token``)."""
        return self.admin_token

    # ---- clients and tokens ---------------------------------------------------------------------------

    def client(self, token: str | None = None) -> HgrenderClient:
        """A new client (close it: ``with service.client(token) as client``); default: the admin's."""
        return HgrenderClient(self.base_url, token=token if token is not None else self.admin_token)

    @property
    def admin(self) -> HgrenderClient:
        """The admin's client, open while the service runs."""
        if self._admin is None:
            self._admin = self.client()
        return self._admin

    def new_token(self, owner: str, scopes: tuple[str, ...] = ("submit", "read")) -> str:
        secret, _ = TokenRegistry(self.redis).create(owner, scopes)
        return secret

    def get(self, path: str, token: str | None = None, **params: Any) -> httpx.Response:
        """``GET path`` with ``token`` (default: the admin's; ``""``: none) and query ``params``."""
        token = self.admin_token if token is None else token
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.get(self.base_url + path, headers=headers, params=params, timeout=60)

    @property
    def jobs(self) -> JobService:
        """The API's job service over this service's Redis and store (to read what workers wrote)."""
        return JobService(JobLifecycle(self.redis, store_from_settings(self.settings)), self.settings)

    def steps(self, job_id: str) -> JobSteps:
        """The job's steps as the workers booked them (pids, attempts, completions, ...)."""
        return self.jobs.lifecycle.steps(job_id)

    # ---- workers --------------------------------------------------------------------------------------

    def start_worker(self, name: str | None = None, **env_overrides: str) -> subprocess.Popen[bytes]:
        """An ``hgrender worker`` subprocess in its own session (so a test can kill all of it)."""
        env = {**os.environ, **self.settings.to_env(), **env_overrides}
        command = worker_command_line(*(["--name", name] if name else []))
        log = (self.data_dir / f"worker-{name or len(self.workers)}.log").open("wb")
        process = subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        self.workers.append(process)
        return process

    def ensure_worker(self) -> None:
        """At least one worker runs (one is started unless a started one is still alive)."""
        if not any(process.poll() is None for process in self.workers):
            self.start_worker()

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

    # ---- jobs -----------------------------------------------------------------------------------------

    def wait_final(self, job_id: str, timeout_s: float = 120.0) -> dict[str, Any]:
        """Poll the job until a final status (fails the test after ``timeout_s``, so that a job stuck in
        a broken worker cannot hang the suite)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            view = self.admin.get(job_id)
            if view["status"] in FINAL_STATUSES:
                return view
            time.sleep(0.2)
        pytest.fail(f"job {job_id} not finished after {timeout_s} s: {self.admin.get(job_id)}")

    def backlog(self, count: int, scene: dict[str, Any], **options: Any) -> list[str]:
        """Stop every worker and submit ``count`` jobs of ``scene`` (as the admin): a queue that the
        workers a test starts next find full. Their ids, in submission order."""
        self.stop_workers()
        return [self.admin.submit(scene, **options)["id"] for _ in range(count)]

    def render(self, scene: dict[str, Any], name: str, **options: Any) -> str:
        """Submit (as the admin), make sure a worker runs, and wait for success; returns the job id."""
        self.ensure_worker()
        job = self.admin.submit(scene, name=name, **options)
        final = self.wait_final(job["id"])
        assert final["status"] == "succeeded", final
        return job["id"]

    def render_image(self, scene: dict[str, Any], name: str) -> RenderedJob:
        """``render``, then download and read the job's ``image.exr``."""
        job_id = self.render(scene, name)
        path = self.data_dir / f"{job_id}.exr"
        self.admin.download(job_id, "image.exr", path)
        return RenderedJob(job_id, read_exr(path))


@contextlib.contextmanager
def running_service(redis_url: str, data_dir: Path) -> Iterator[LiveService]:
    """The API on a free loopback port over a flushed Redis (state from earlier modules is gone); stops its
    workers and the API on exit."""
    client = redis.Redis.from_url(redis_url)
    client.flushdb()
    settings = fast_settings(redis_url, data_dir)
    admin_token = ensure_admin_token(client, data_dir / "admin.token")
    port = free_loopback_port()
    server = _ThreadedServer(
        uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started:
        if time.monotonic() > deadline:
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.05)
    service = LiveService(settings, f"http://127.0.0.1:{port}", admin_token, client)
    try:
        yield service
    finally:
        service.stop_workers()
        if service._admin is not None:
            service._admin.close()
        server.should_exit = True
        thread.join(timeout=10)
        client.close()
