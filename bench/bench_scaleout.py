"""Throughput of chunked renders through the service with 1, 2 and 4 worker processes (issue 8).

For each worker count N a fresh ``hgrender serve --workers N`` (private Redis, temporary data dir,
auth off, one Dr.Jit thread per worker) renders the same batch of chunked jobs; the clock runs from
the first submission to the last job's ``succeeded``. Reported: jobs/hour and the scaling efficiency
E_N = (throughput_N / throughput_1) / N, whose goal is ≥ 0.9 while N ≤ cores. A warm-up job per
server fills Dr.Jit's kernel cache first, so compilation is excluded. Workers run on loopback only
(the namespaced multi-host set-up is exercised by tests/deploy/test_multihost.py, not timed here).

Run: ``.venv/bin/python -m bench.bench_scaleout [--jobs 8] [--workers 1,2,4]``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.machine import cpu_model, cpu_reference_s, write_results
from hgrender.client import HgrenderClient
from schemas import EXAMPLES_DIR


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _scene(size_px: int, spp: int) -> dict[str, Any]:
    scene = json.loads((EXAMPLES_DIR / "cornell_box.json").read_text())
    scene["film"] = {**scene["film"], "width": size_px, "height": size_px, "spp": spp}
    return scene


def measure(workers: int, jobs: int, chunks: int, size_px: int, spp: int) -> dict[str, Any]:
    """Jobs/hour of ``jobs`` chunked renders on a fresh server with ``workers`` worker processes."""
    port = _free_port()
    with tempfile.TemporaryDirectory(prefix="hgrender-bench-") as data_dir:
        # One render thread per worker: a worker stands for one core (or one machine) of a scale-out.
        env = {
            **os.environ,
            "HGRENDER_AUTH": "off",
            "HGRENDER_REGRESSION_SCHEDULER": "false",
            "HGRENDER_RENDER_THREADS": "1",
        }
        env.pop("REDIS_URL", None)
        server = subprocess.Popen(
            [
                str(Path(sys.executable).parent / "hgrender"),
                "serve",
                "--port",
                str(port),
                "--data-dir",
                data_dir,
                "--workers",
                str(workers),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            client = HgrenderClient(f"http://127.0.0.1:{port}")
            deadline = time.monotonic() + 120
            while True:
                try:
                    client.health()
                    break
                except Exception:  # the server is still starting
                    if time.monotonic() > deadline or server.poll() is not None:
                        raise RuntimeError(f"hgrender serve --workers {workers} did not start") from None
                    time.sleep(0.5)
            warm = client.submit(_scene(size_px, spp), chunks=workers)
            client.wait(warm["id"], timeout_s=600, poll_interval_s=0.2)
            start = time.perf_counter()
            submitted = [
                client.submit(_scene(size_px, spp), chunks=chunks, seed=i)["id"] for i in range(jobs)
            ]
            statuses = [
                client.wait(job_id, timeout_s=1800, poll_interval_s=0.2)["status"] for job_id in submitted
            ]
            seconds = time.perf_counter() - start
            client.close()
        finally:
            os.killpg(server.pid, signal.SIGTERM)
            try:
                server.wait(timeout=120)
            except subprocess.TimeoutExpired:
                os.killpg(server.pid, signal.SIGKILL)
    return {
        "workers": workers,
        "jobs": jobs,
        "seconds": seconds,
        "jobs_per_hour": jobs / seconds * 3600.0,
        "succeeded": statuses.count("succeeded"),
    }


def main(
    jobs: int = 8, workers: tuple[int, ...] = (1, 2, 4), chunks: int = 4, size_px: int = 64, spp: int = 512
) -> dict[str, Any]:
    runs = [measure(count, jobs, chunks, size_px, spp) for count in workers]
    baseline = runs[0]["jobs_per_hour"] / runs[0]["workers"]
    for run in runs:
        run["efficiency"] = run["jobs_per_hour"] / (baseline * run["workers"])
    result = {
        "cores": os.cpu_count(),
        "cpu": cpu_model(),
        "cpu_reference_s": cpu_reference_s(),
        "scene": f"cornell_box {size_px}x{size_px}, {spp} spp, {chunks} chunks per job",
        "runs": runs,
        "goal": "efficiency >= 0.9 while workers <= cores",
        "goal_met": all(run["efficiency"] >= 0.9 for run in runs if run["workers"] <= (os.cpu_count() or 1)),
    }
    write_results("scaleout", result)
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=8)
    parser.add_argument("--workers", default="1,2,4")
    arguments = parser.parse_args()
    print(json.dumps(main(arguments.jobs, tuple(int(n) for n in arguments.workers.split(","))), indent=2))
