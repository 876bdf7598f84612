"""Graceful worker shutdown on SIGTERM (issue 8), with real Redis, real ``hgrender worker`` subprocesses
and the real renderer: a chunk that ends within ``HGRENDER_WORKER_SHUTDOWN_GRACE_S`` is finished by the
stopping worker; one that does not is handed back to the queue (no retry spent) and finished by another
worker; a second SIGTERM hands it back at once. In every case each chunk and the merge complete exactly
once and the job has one set of artifacts.

Jobs have two chunks, so that a stopping worker leaves work in the queue for the next one. Render lengths
follow the service tests' calibration: the Cornell box at 64x64 px takes about spp / 700 s on 2 shared
cores, so a chunk of a ``spp = 2048`` job runs ~1.5 s and one of a ``spp = 8192`` job ~6 s (longer than
any grace used here).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from hgcore.jobs.queue_graph import chunk_rq_id
from hgrender.client import HgrenderClient
from tests.support.live_service import LiveService
from tests.support.processes import wait_for
from tests.support.scenes import tiny_scene

pytestmark = pytest.mark.slow


def submit_rendering(service: LiveService, spp: int) -> tuple[HgrenderClient, str, int]:
    """Submit a two-chunk Cornell box job (``spp`` in all) and wait until chunk 0 renders; return its
    horse's pid. With one worker, chunk 1 and the merge wait in the queue meanwhile."""
    client = service.client()
    job_id = client.submit(tiny_scene(size_px=64, spp=spp), chunks=2)["id"]
    wait_for(
        lambda: (v := client.get(job_id))["status"] == "running" and v["chunks"][0]["progress"] > 0,
        60,
        "the chunk to render",
    )
    return client, job_id, service.steps(job_id).chunks[0].pid


def wait_exit(process: subprocess.Popen[bytes], timeout_s: float) -> int:
    try:
        return process.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        pytest.fail(f"worker {process.pid} still running {timeout_s} s after SIGTERM")


def assert_succeeded_exactly_once(
    service: LiveService, client: HgrenderClient, job_id: str
) -> dict[str, Any]:
    final = client.wait(job_id, timeout_s=180)
    assert final["status"] == "succeeded", final.get("error")
    assert service.steps(job_id).completions() == {"0": 1, "1": 1, "merge": 1}
    names = [a["name"] for a in client.artifacts(job_id)]
    assert len(names) == len(set(names)) and names.count("image.exr") == 1
    assert sorted(n for n in names if n.startswith("chunks/")) == ["chunks/0.npz", "chunks/1.npz"]
    return final


def assert_handed_back(service: LiveService, job_id: str, horse_pid: int) -> None:
    """The chunk is queued again with every retry left, its horse is gone and nothing completed."""
    rq_job = RQJob.fetch(chunk_rq_id(job_id, 0), connection=service.redis)
    assert rq_job.get_status() == RQJobStatus.QUEUED
    assert rq_job.retries_left == service.settings.chunk_retry_max
    assert not os.path.exists(f"/proc/{horse_pid}")
    assert service.steps(job_id).completions() == {}


@pytest.fixture
def service(live_service: LiveService) -> Iterator[LiveService]:
    live_service.stop_workers()
    yield live_service
    live_service.stop_workers()


def test_sigterm_lets_the_current_chunk_finish_within_the_grace(service: LiveService) -> None:
    stopping = service.start_worker("stopping", HGRENDER_WORKER_SHUTDOWN_GRACE_S="120")
    client, job_id, _ = submit_rendering(service, spp=2048)
    stopping.send_signal(signal.SIGTERM)  # to the worker only, as Kubernetes signals a container's PID 1
    assert wait_exit(stopping, 60) == 0
    # The stopping worker finished its chunk but took nothing new (chunk 1 and the merge wait).
    assert service.steps(job_id).completions() == {"0": 1}
    assert client.get(job_id)["status"] == "running"
    service.start_worker("merger")
    final = assert_succeeded_exactly_once(service, client, job_id)
    assert final["chunks"][0]["attempts"] == 1 and final["chunks"][0]["worker"] == "stopping"


def test_sigterm_hands_the_chunk_back_after_the_grace(service: LiveService) -> None:
    """Grace 1 s, heartbeat tick 1 s: the hand-back comes 1–2 s after SIGTERM; the bound of 15 s leaves
    room for the exit (RQ scheduler stop, deregistration) on busy shared cores."""
    stopping = service.start_worker("stopping", HGRENDER_WORKER_SHUTDOWN_GRACE_S="1")
    client, job_id, horse_pid = submit_rendering(service, spp=8192)
    signaled_s = time.monotonic()
    stopping.send_signal(signal.SIGTERM)
    assert wait_exit(stopping, 15) == 0
    assert time.monotonic() - signaled_s < 15
    assert_handed_back(service, job_id, horse_pid)
    service.start_worker("taker")
    final = assert_succeeded_exactly_once(service, client, job_id)
    assert final["chunks"][0]["attempts"] == 2 and final["chunks"][0]["worker"] == "taker"


def test_second_sigterm_hands_the_chunk_back_at_once(service: LiveService) -> None:
    stopping = service.start_worker("stopping", HGRENDER_WORKER_SHUTDOWN_GRACE_S="120")
    client, job_id, horse_pid = submit_rendering(service, spp=8192)
    stopping.send_signal(signal.SIGTERM)
    time.sleep(1.5)  # RQ ignores a repeated signal within 1 s (the duplicate a worker pool sends)
    stopping.send_signal(signal.SIGTERM)
    wait_exit(stopping, 15)
    assert_handed_back(service, job_id, horse_pid)
    service.start_worker("taker")
    final = assert_succeeded_exactly_once(service, client, job_id)
    assert final["chunks"][0]["attempts"] == 2 and final["chunks"][0]["worker"] == "taker"
