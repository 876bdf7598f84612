"""API and queue benchmark (issue 5 targets): ``GET /v1/jobs/{id}`` requests/s and p99 latency, job
submissions/s, and the queue overhead of an empty render job (submit → succeeded, p50).

Everything runs against ``hgrender serve`` subprocesses on loopback with their private Redis; the load
comes from a separate process: ``wrk`` when installed (C, negligible client cost), else a pool of
Python processes with httpx keep-alive clients. The read and submit phases run on a server without
workers (so rendering does not compete for the cores); the overhead phase uses a server with one worker
and submits sequentially a 1x1-pixel, 1-spp, 1-band scene. Its end-to-end time includes the renderer's
scene compilation and the merge's EXR/PNG writing (``render_s`` + ``merge_s`` of the job's timings);
``empty_job_queue_share_p50_ms`` is the rest: API, Redis, dequeue, fork, uploads, bookkeeping. A 1-spp
job has one chunk, so it runs as a single RQ job that renders and merges in one work horse.
Run: ``python -m bench.bench_api`` (or ``python -m bench`` for every benchmark); results also go to
``bench/results/api.json``. ``cpu_reference_s`` tells how fast the (shared) machine was during the run.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

from bench.machine import cpu_model, cpu_reference_s, write_results
from hgrender.client import HgrenderClient
from schemas import EXAMPLES_DIR
from service.redis_server import free_loopback_port

SCENE_PATH = EXAMPLES_DIR / "cornell_box.json"
LOAD_DURATION_S = 10.0
CONNECTIONS = 8
OVERHEAD_JOBS = 60


def empty_scene() -> dict[str, Any]:
    """The Cornell box reduced to 1x1 px, 1 spp, 1 band: a job whose render costs almost nothing."""
    scene = json.loads(SCENE_PATH.read_text())
    scene["film"].update({"width": 1, "height": 1, "spp": 1, "bands": 1})
    return scene


@contextmanager
def serve(data_dir: Path, workers: int) -> Iterator[tuple[str, str]]:
    """``hgrender serve`` with its own Redis; yields (base URL, admin token)."""
    port = free_loopback_port()
    env = {k: v for k, v in os.environ.items() if k != "REDIS_URL" and not k.startswith("HGRENDER_")}
    env["HGRENDER_RATE_LIMIT_PER_MINUTE"] = str(10**9)  # measure the server, not the limiter
    command = [sys.executable, "-c", "import sys; from hgrender.cli import main; sys.exit(main())", "serve"]
    command += ["--port", str(port), "--data-dir", str(data_dir), "--workers", str(workers)]
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                response = httpx.get(url + "/readyz", timeout=1)
                # /readyz also needs a live worker; a server started without workers is ready for this
                # benchmark once its API and Redis answer.
                if response.status_code == 200 or (
                    workers == 0 and response.json()["checks"]["redis"] == "ok"
                ):
                    break
            except (httpx.HTTPError, ValueError, KeyError):
                pass
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError("hgrender serve did not become ready")
            time.sleep(0.2)
        yield url, (data_dir / "admin.token").read_text().strip()
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            process.kill()


# ---- load generators -----------------------------------------------------------------------------------

_WRK_UNITS_S = {"us": 1e-6, "ms": 1e-3, "s": 1.0, "m": 60.0}


def _wrk(url: str, token: str, duration_s: float, body: bytes | None) -> dict[str, float]:
    """Run wrk (2 threads, CONNECTIONS connections) and parse requests/s and latency percentiles."""
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "request.lua"
        lines = [f'wrk.headers["Authorization"] = "Bearer {token}"']
        if body is not None:
            (Path(tmp) / "body.json").write_bytes(body)
            lines += [
                'wrk.method = "POST"',
                'wrk.headers["Content-Type"] = "application/json"',
                f'local f = io.open("{Path(tmp) / "body.json"}", "rb"); wrk.body = f:read("*a"); f:close()',
            ]
        lines += [
            "local non2xx = 0",
            "response = function(status, headers, body) if status >= 300 then non2xx = non2xx + 1 end end",
        ]
        script.write_text("\n".join(lines) + "\n")
        output = subprocess.run(
            ["wrk", "-t2", f"-c{CONNECTIONS}", f"-d{int(duration_s)}s", "--latency", "-s", str(script), url],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    percentiles = {
        int(p): float(v) * _WRK_UNITS_S[u]
        for p, v, u in re.findall(r"^\s+(\d+)%\s+([\d.]+)(us|ms|s|m)\s*$", output, re.M)
    }
    errors = re.search(r"Non-2xx or 3xx responses: (\d+)", output)
    return {
        "requests_per_s": float(re.search(r"Requests/sec:\s+([\d.]+)", output).group(1)),  # type: ignore[union-attr]
        "p50_ms": percentiles[50] * 1e3,
        "p99_ms": percentiles[99] * 1e3,
        "non_2xx": float(errors.group(1)) if errors else 0.0,
        "tool": 1.0,
    }


def _python_load_worker(args: tuple[str, str, float, bytes | None, int]) -> tuple[int, int, list[float]]:
    url, token, duration_s, body, _connections = args
    latencies: list[float] = []
    failures = 0
    headers = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}
    with httpx.Client(headers=headers, timeout=30) as client:
        end = time.perf_counter() + duration_s
        while (start := time.perf_counter()) < end:
            response = client.post(url, content=body) if body is not None else client.get(url)
            latencies.append(time.perf_counter() - start)
            failures += response.status_code >= 300
    return len(latencies), failures, latencies


def _python_load(url: str, token: str, duration_s: float, body: bytes | None) -> dict[str, float]:
    """Fallback without wrk: 2 client processes with keep-alive connections."""
    processes = 2
    with multiprocessing.get_context("spawn").Pool(processes) as pool:
        results = pool.map(_python_load_worker, [(url, token, duration_s, body, 1)] * processes)
    latencies = sorted(x for _, _, lat in results for x in lat)
    count = sum(n for n, _, _ in results)
    return {
        "requests_per_s": count / duration_s,
        "p50_ms": latencies[len(latencies) // 2] * 1e3,
        "p99_ms": latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))] * 1e3,
        "non_2xx": float(sum(f for _, f, _ in results)),
        "tool": 0.0,
    }


def load(url: str, token: str, duration_s: float, body: bytes | None = None) -> dict[str, float]:
    if shutil.which("wrk"):
        return _wrk(url, token, duration_s, body)
    return _python_load(url, token, duration_s, body)


# ---- phases --------------------------------------------------------------------------------------------


def queue_overhead(url: str, token: str, jobs: int) -> dict[str, float]:
    """Sequential empty jobs: seconds from POST to the client reading ``succeeded`` (it follows the job's
    events, as ``hgrender submit --wait`` does), and the queue's own share of it: total minus the
    renderer's chunk and merge compute (server timings)."""
    end_to_end_s, queue_share_s = [], []
    with HgrenderClient(url, token) as client:
        scene = empty_scene()
        client.wait(client.submit(scene)["id"], timeout_s=120)  # warm the kernel cache
        for _ in range(jobs):
            start = time.perf_counter()
            job_id = client.submit(scene)["id"]
            view = client.wait(job_id, timeout_s=120)
            end_to_end_s.append(time.perf_counter() - start)
            if view["status"] != "succeeded":
                raise RuntimeError(f"empty job {job_id} ended {view['status']}: {view.get('error')}")
            timings = view["timings"]
            queue_share_s.append(
                timings["total_s"] - (timings["render_s"] or 0.0) - (timings["merge_s"] or 0.0)
            )
    return {
        "p50_ms": statistics.median(end_to_end_s) * 1e3,
        "p90_ms": statistics.quantiles(end_to_end_s, n=10)[-1] * 1e3,
        "queue_share_p50_ms": statistics.median(queue_share_s) * 1e3,
        "jobs": float(jobs),
    }


def main() -> dict[str, Any]:
    reference_before_s = cpu_reference_s()
    with tempfile.TemporaryDirectory(prefix="hgrender-bench-") as tmp:
        with serve(Path(tmp) / "api", workers=0) as (url, token):
            with HgrenderClient(url, token) as client:
                job_id = client.submit(empty_scene(), chunks=2)["id"]
            get = load(f"{url}/v1/jobs/{job_id}", token, LOAD_DURATION_S)
            body = json.dumps({"scene": empty_scene(), "priority": "low", "chunks": 1}).encode()
            submit = load(f"{url}/v1/jobs", token, LOAD_DURATION_S, body)
        with serve(Path(tmp) / "queue", workers=1) as (url, token):
            overhead = queue_overhead(url, token, OVERHEAD_JOBS)
    results = {
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "cpu_reference_s": [reference_before_s, cpu_reference_s()],  # before and after the phases
        "load_generator": "wrk" if get["tool"] else "python-httpx",
        "connections": CONNECTIONS,
        "get_job_requests_per_s": get["requests_per_s"],
        "get_job_p50_ms": get["p50_ms"],
        "get_job_p99_ms": get["p99_ms"],
        "get_job_errors": get["non_2xx"],
        "submissions_per_s": submit["requests_per_s"],
        "submission_p99_ms": submit["p99_ms"],
        "submission_errors": submit["non_2xx"],
        "empty_job_overhead_p50_ms": overhead["p50_ms"],
        "empty_job_overhead_p90_ms": overhead["p90_ms"],
        "empty_job_queue_share_p50_ms": overhead["queue_share_p50_ms"],
        "targets": {
            "get_job_requests_per_s": ">= 1500",
            "get_job_p99_ms": "< 20",
            "submissions_per_s": ">= 300",
            "empty_job_overhead_p50_ms": "< 100",
        },
    }
    write_results("api", results)
    return results


if __name__ == "__main__":
    json.dump(main(), sys.stdout, indent=2)
    sys.stdout.write("\n")
