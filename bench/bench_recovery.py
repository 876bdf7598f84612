"""How soon finished work completes behind a backlog, and how soon a killed chunk runs again (issue 17).

One ``hgrender serve --workers 1`` (default timing settings, auth off) over a Redis of its own renders a
backlog of ``--jobs`` two-chunk jobs submitted at once. Reported:

- ``merge_wait_s``: per job, from its last chunk's end to its merge's start (median and max). Before
  issue 17 a merge was enqueued behind the whole backlog (46 s with 10 jobs on the shared machine).
- ``finish_order``: job finish order as submission indices, and ``inversions`` (pairs finished out of
  submission order).
- ``retry_after_kill_s``: the first job's chunk 0 has its work horse SIGKILLed while it renders; time until
  its second attempt starts (retry interval 2 s; before issue 17 it waited for the backlog: 50–70 s).

Run: ``.venv/bin/python -m bench.bench_recovery [--jobs 10]`` (``PYTHONPATH`` selects the code measured).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median
from typing import Any

import redis

from bench.bench_scaleout import _scene  # the same Cornell box scene
from bench.machine import cpu_model, cpu_reference_s, write_results
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.store.filesystem import FilesystemStore
from hgrender.client import HgrenderClient
from service.redis_server import RedisServer, free_loopback_port


def _retry_started_at(lifecycle: JobLifecycle, job_id: str) -> float | None:
    """When chunk 0's second attempt started (None before it did)."""
    chunk = lifecycle.steps(job_id).chunks[0]
    return chunk.started_at if chunk.attempts == 2 else None


def _wait(predicate: Any, timeout_s: float) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if value := predicate():
            return value
        time.sleep(0.05)
    raise TimeoutError("benchmark step timed out")


def measure(jobs: int, size_px: int, spp: int) -> dict[str, Any]:
    port = free_loopback_port()
    with (
        tempfile.TemporaryDirectory(prefix="hgrender-bench-") as data_dir,
        RedisServer(Path(data_dir) / "redis") as redis_server,
    ):
        env = {k: v for k, v in os.environ.items() if not k.startswith("HGRENDER_")}
        env |= {
            "REDIS_URL": redis_server.url,
            "HGRENDER_AUTH": "off",
            "HGRENDER_REGRESSION_SCHEDULER": "false",
            "HGRENDER_RENDER_THREADS": "1",
        }
        command = [sys.executable, "-c", "import sys; from hgrender.cli import main; sys.exit(main())"]
        server = subprocess.Popen(
            [*command, "serve", "--port", str(port), "--data-dir", data_dir, "--workers", "1"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        redis_client = redis.Redis.from_url(redis_server.url)
        # The job's steps as the workers booked them, read through their owner (hgcore.jobs.lifecycle).
        lifecycle = JobLifecycle(redis_client, FilesystemStore(Path(data_dir) / "artifacts"))
        try:
            with HgrenderClient(f"http://127.0.0.1:{port}") as client:
                _wait(lambda: _answers(client), 60)
                warm = client.submit(_scene(size_px, 2), chunks=2)["id"]  # Dr.Jit's kernel cache
                client.wait(warm, timeout_s=300)
                job_ids = [client.submit(_scene(size_px, spp), chunks=2)["id"] for _ in range(jobs)]
                _wait(lambda: lifecycle.steps(job_ids[0]).chunks[0].progress > 0, 120)
                killed_at = time.time()
                pid = lifecycle.steps(job_ids[0]).chunks[0].pid
                assert pid is not None, "a chunk with progress has a pid"
                os.kill(pid, signal.SIGKILL)
                retried_at = _wait(lambda: _retry_started_at(lifecycle, job_ids[0]), 600)
                finals = [client.wait(job_id, timeout_s=900) for job_id in job_ids]
        finally:
            server.send_signal(signal.SIGTERM)
            server.wait(timeout=120)
        waits = []
        for job_id in job_ids:
            steps = lifecycle.steps(job_id)
            assert steps.merge is not None and steps.merge.started_at is not None, job_id
            ends = [chunk.finished_at for chunk in steps.chunks]
            assert None not in ends, job_id
            last_chunk_end = max(end for end in ends if end is not None)
            waits.append(steps.merge.started_at - last_chunk_end)
        order = sorted(range(jobs), key=lambda i: finals[i]["timings"]["finished_at"])
        inversions = sum(
            1 for a in range(jobs) for b in range(a + 1, jobs) if order.index(a) > order.index(b)
        )
        redis_client.close()
    return {
        "jobs": jobs,
        "size_px": size_px,
        "spp": spp,
        "all_succeeded": all(f["status"] == "succeeded" for f in finals),
        "merge_wait_s": {"median": round(median(waits), 2), "max": round(max(waits), 2)},
        "finish_order": order,
        "inversions": inversions,
        "retry_after_kill_s": round(retried_at - killed_at, 2),
        "backlog_s": round(max(f["timings"]["finished_at"] for f in finals) - killed_at, 1),
    }


def _answers(client: HgrenderClient) -> bool:
    try:
        client.list()
        return True
    except Exception:
        return False


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=10)
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--spp", type=int, default=8192)
    parser.add_argument("--output", default="recovery", help="bench/results/<output>.json")
    args = parser.parse_args(argv if argv is not None else [])
    results = {
        "cpu_model": cpu_model(),
        "cpu_reference_s": cpu_reference_s(),
        "note": "shared 2-core machine; one worker",
        **measure(args.jobs, args.size, args.spp),
    }
    write_results(args.output, results)
    return results


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:]), indent=2))
