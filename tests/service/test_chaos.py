"""Chaos (issue 17): ``hgrender serve`` with its private Redis renders a batch of small multi-chunk jobs
while a driver with a fixed seed kills, at random moments, work horses, whole workers, the RQ scheduler
and the private Redis, and once SIGTERMs ``serve`` itself and starts it again. Afterwards every job
succeeded exactly once (one transition each: the by-state counters), its artifacts match its manifest, no
temporary or partial file is left, and none of the processes seen is still running.

Timing settings are the fast ones of the other service tests (heartbeat 1 + 3 s, maintenance every 2 s),
so that the batch ends within about a minute on 2 shared cores; retries are 5 instead of 3 because the
driver may hit one chunk more than three times. Each kill waits (up to 30 s) for its target to exist, and
the horse kill submits one more job when the batch has ended, so that every kind of kill happens whatever
the machine's speed; a job the driver adds must succeed exactly once like the first twenty.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import re
import signal
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
import redis

from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.status import TERMINAL_STATUSES
from hgcore.store.filesystem import FilesystemStore
from hgrender.client import HgrenderClient
from service.redis_server import free_loopback_port
from tests.support.processes import children_of, describe_process, is_alive, wait_for
from tests.support.scenes import tiny_scene
from tests.support.serve import redis_servers_in, start_serve, stop_serve

pytestmark = pytest.mark.slow

SEED = 20261201
JOBS = 20
CHAOS_ENV = {
    "HGRENDER_WORKER_MONITORING_INTERVAL_S": "1",
    "HGRENDER_WORKER_HEARTBEAT_GRACE_S": "3",
    "HGRENDER_WORKER_MAINTENANCE_INTERVAL_S": "2",
    "HGRENDER_CHUNK_RETRY_INTERVALS_S": "[1]",
    "HGRENDER_CHUNK_RETRY_MAX": "5",
    "HGRENDER_WORKER_SHUTDOWN_GRACE_S": "2",
    "HGRENDER_REGRESSION_SCHEDULER": "false",
    "HGRENDER_RENDER_THREADS": "1",
    "HGRENDER_RECONCILE_INTERVAL_S": "5",
}


class Chaos:
    """The running ``serve`` and what the driver can kill in it; every pid it saw is remembered."""

    def __init__(self, data_dir: Path, port: int) -> None:
        self.data_dir, self.port = data_dir, port
        self.url = f"http://127.0.0.1:{port}"
        self.serve = start_serve(data_dir, port, workers=2, extra_env=CHAOS_ENV)
        self.seen: set[int] = set()
        self.log: list[str] = []
        self.api_back_s: list[float] = []
        self.token = (data_dir / "admin.token").read_text().strip()

    def submit(self) -> str:
        with HgrenderClient(self.url, self.token) as client:
            return client.submit(tiny_scene(size_px=32, spp=512), chunks=2)["id"]

    def redis(self) -> redis.Redis:
        return redis.Redis.from_url(self._redis_url(), socket_connect_timeout=1)

    def jobs(self) -> JobLifecycle:
        """The jobs of the current private Redis (it moves when it restarts)."""
        return JobLifecycle(self.redis(), FilesystemStore(self.data_dir / "artifacts"))

    def _redis_url(self) -> str:
        for proc_pid in redis_servers_in(self.data_dir / "redis"):
            # redis-server sets its process title to "redis-server 127.0.0.1:<port>".
            title = Path(f"/proc/{proc_pid}/cmdline").read_bytes().decode(errors="replace")
            port = re.search(r"127\.0\.0\.1:(\d+)", title)
            if port:
                return f"redis://127.0.0.1:{port.group(1)}/0"
        raise RuntimeError("no private redis-server")

    def workers(self) -> list[int]:
        return [
            p for p in children_of(self.serve.pid) if b"worker" in Path(f"/proc/{p}/cmdline").read_bytes()
        ]

    def _kill(self, what: str, pid: int, sig: signal.Signals = signal.SIGKILL) -> None:
        self.seen.add(pid)
        self.seen.update(c for w in self.workers() for c in children_of(w))
        self.log.append(f"{time.monotonic():.1f} {sig.name} {what} {pid}")
        try:
            os.kill(pid, sig)
        except ProcessLookupError:  # it ended by itself since it was found (a horse finishing its chunk)
            self.log.append(f"{time.monotonic():.1f} {what} {pid} had already exited")

    def _wait_for_target(
        self, rng: random.Random, find: Callable[[], list[int]], what: str, timeout_s: float = 30.0
    ) -> int | None:
        """A live pid ``find`` names, polled until one exists: a kill must not be skipped because the
        driver looked in the moment between two chunks (or while Redis or a worker restarts)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                pids = [p for p in find() if is_alive(p)]
            except (redis.RedisError, RuntimeError, ValueError):  # Redis restarting: look again
                pids = []
            if pids:
                return rng.choice(pids)
            time.sleep(0.05)
        self.log.append(f"{time.monotonic():.1f} no {what} within {timeout_s:.0f} s")
        return None

    def _running_horses(self, job_ids: list[str]) -> list[int]:
        jobs = self.jobs()
        pids: list[int] = []
        for job_id in job_ids:
            steps = jobs.steps(job_id)
            running = [*steps.chunks, *([steps.merge] if steps.merge is not None else [])]
            pids += [step.pid for step in running if step.status == "running" and step.pid is not None]
        return pids

    def _unfinished(self, job_ids: list[str]) -> int:
        jobs = self.jobs()
        return sum(jobs.status(j) not in TERMINAL_STATUSES for j in job_ids)

    def kill_horse(self, rng: random.Random, job_ids: list[str]) -> None:
        # Keep work in the queue so that a horse will run: when every submitted job has ended, the driver
        # submits one more (and every job it submitted must succeed exactly once like the others).
        try:
            if self._unfinished(job_ids) == 0:
                job_ids.append(self.submit())
        except redis.RedisError:
            pass
        pid = self._wait_for_target(rng, lambda: self._running_horses(job_ids), "running horse")
        if pid is not None:
            self._kill("horse", pid)

    def kill_worker(self, rng: random.Random, _: list[str]) -> None:
        pid = self._wait_for_target(rng, self.workers, "worker")
        if pid is not None:
            self._kill("worker", pid)

    def kill_scheduler(self, rng: random.Random, _: list[str]) -> None:
        def scheduler() -> list[int]:
            client = self.redis()
            holder = client.get("rq:scheduler-lock:default")
            pid = client.hget(f"rq:scheduler:{holder.decode()}", "pid") if holder else None
            return [int(pid)] if pid else []

        pid = self._wait_for_target(rng, scheduler, "scheduler")
        if pid is not None:
            self._kill("scheduler", pid)

    def kill_redis(self, _rng: random.Random, job_ids: list[str]) -> None:
        (pid,) = redis_servers_in(self.data_dir / "redis")
        self._kill("redis", pid)
        killed_at = time.monotonic()
        token = (self.data_dir / "admin.token").read_text().strip()

        def answers() -> bool:
            try:
                response = httpx.get(
                    f"{self.url}/v1/jobs/{job_ids[0]}",
                    headers={"Authorization": f"Bearer {token}"},
                    timeout=2,
                )
                return response.status_code == 200
            except httpx.HTTPError:
                return False

        wait_for(answers, 30, "the API to answer after the Redis kill", interval_s=0.1)
        self.api_back_s.append(time.monotonic() - killed_at)

    def restart_serve(self, _rng: random.Random, _: list[str]) -> None:
        self.seen.update(self.workers())
        self.seen.update(redis_servers_in(self.data_dir / "redis"))
        self.log.append(f"{time.monotonic():.1f} SIGTERM serve {self.serve.pid}")
        stop_serve(self.serve)
        self.serve = start_serve(self.data_dir, self.port, workers=2, extra_env=CHAOS_ENV)


def test_every_job_succeeds_exactly_once_under_chaos(tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    chaos = Chaos(data_dir, free_loopback_port())
    token = (data_dir / "admin.token").read_text().strip()
    rng = random.Random(SEED)
    try:
        job_ids = [chaos.submit() for _ in range(JOBS)]
        actions: list[Callable[[random.Random, list[str]], None]] = [
            chaos.kill_horse,
            chaos.kill_horse,
            chaos.kill_worker,
            chaos.kill_scheduler,
            chaos.kill_redis,
            chaos.kill_horse,
            chaos.kill_worker,
            chaos.kill_redis,
            chaos.kill_scheduler,
        ]
        rng.shuffle(actions)
        actions.insert(len(actions) // 2, chaos.restart_serve)
        for action in actions:
            time.sleep(rng.uniform(0.5, 2.5))
            action(rng, job_ids)

        def all_ended() -> dict[str, str] | None:
            try:
                with HgrenderClient(chaos.url, token) as client:
                    statuses = {j: client.get(j)["status"] for j in job_ids}
            except Exception:  # the API may be between restarts
                return None
            return (
                statuses if all(s in {"succeeded", "failed", "canceled"} for s in statuses.values()) else None
            )

        statuses = wait_for(all_ended, 150, "every job to end", interval_s=0.5)
        print("\n".join(chaos.log))
        print(f"API answered again {chaos.api_back_s} s after each Redis kill")
        assert statuses == dict.fromkeys(job_ids, "succeeded"), chaos.log
        for kind in (
            "SIGKILL horse",
            "SIGKILL worker",
            "SIGKILL scheduler",
            "SIGKILL redis",
            "SIGTERM serve",
        ):
            assert any(kind in line for line in chaos.log), f"the driver never did {kind}: {chaos.log}"
        assert chaos.api_back_s and max(chaos.api_back_s) <= 10.0
        counts = chaos.jobs().counts_by_state()
        assert {k: v for k, v in counts.items() if v} == {"succeeded": len(job_ids)}  # one transition per job
        artifacts = data_dir / "artifacts" / "jobs"
        for job_id in job_ids:
            manifest = json.loads((artifacts / job_id / "manifest.json").read_text())
            assert manifest["job"]["status"] == "succeeded"
            listed = {a["name"]: a["sha256"] for a in manifest["artifacts"]}
            on_disk = {
                p.relative_to(artifacts / job_id).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
                for p in (artifacts / job_id).rglob("*")
                if p.is_file() and p.name != "manifest.json"
            }
            assert on_disk == listed, job_id
        partial = [p for p in artifacts.rglob("*") if p.name.startswith(".") or p.suffix in {".tmp", ".part"}]
        assert partial == []
        leftovers = [
            p for p in Path(tempfile.gettempdir()).glob("hgrender-*") if any(j in p.name for j in job_ids)
        ]
        assert leftovers == []
    finally:
        chaos.seen.update(chaos.workers())
        chaos.seen.update(redis_servers_in(data_dir / "redis"))
        stop_serve(chaos.serve)
    deadline = time.monotonic() + 15
    while (lingering := [p for p in chaos.seen if is_alive(p)]) and time.monotonic() < deadline:
        time.sleep(0.1)
    serve_log = (data_dir.parent / f"serve-{chaos.port}.log").read_text(errors="replace").splitlines()
    assert not lingering, (
        "still running 15 s after serve stopped:\n"
        + "\n".join(describe_process(p) for p in lingering)
        + "\nthe end of serve's log:\n"
        + "\n".join(serve_log[-60:])
    )
