"""Reliability over HTTP and through real workers (issue 17): collection limits and messages, strict job
options, client disconnects, cancel bookkeeping, finished work ahead of new chunks, dead-worker recovery
time, the RQ scheduler dying with its worker, and reconciliation of stranded queue state."""

from __future__ import annotations

import itertools
import json
import os
import signal
import socket
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis
from rq.job import Job as RQJob
from rq.scheduler import RQScheduler

from hgcore.jobs.queue_graph import chunk_rq_id, merge_rq_id
from hgcore.jobs.reconcile import QueueReconciler
from tests.support.live_service import LiveService
from tests.support.processes import children_of, is_alive, wait_for
from tests.support.scenes import tiny_scene


def post_job(service: LiveService, body: Any, **kwargs: Any) -> httpx.Response:
    headers = {"Authorization": f"Bearer {service.admin_token}"}
    if isinstance(body, bytes | str):
        headers["Content-Type"] = "application/json"
        return httpx.post(service.base_url + "/v1/jobs", content=body, headers=headers, timeout=30, **kwargs)
    return httpx.post(service.base_url + "/v1/jobs", json=body, headers=headers, timeout=30, **kwargs)


def job_count(service: LiveService) -> int:
    return service.jobs.list(None, None, 0, 1)[1]


# ---- limits and messages (no workers) -------------------------------------------------------------------


def test_twenty_thousand_materials_are_rejected_naming_the_limit(live_service: LiveService) -> None:
    scene = tiny_scene()
    scene["materials"].update({f"unused{i}": {"type": "diffuse"} for i in range(20_000)})
    before = job_count(live_service)
    response = post_job(live_service, {"scene": scene})
    assert response.status_code == 422
    detail = response.json()["detail"]
    assert detail.startswith("scene: /materials: material count 20003 exceeds the limit of 1000")
    assert "HGRENDER_MAX_MATERIALS" in detail
    assert job_count(live_service) == before


@pytest.mark.parametrize(
    ("mutate", "pointer", "variable"),
    [
        (lambda s: s.update(emitters=s["emitters"] * 1001), "/emitters", "HGRENDER_MAX_EMITTERS"),
        (lambda s: s.update(name="n" * 2000), "/name", "HGRENDER_MAX_STRING_CHARS"),
        (lambda s: s.update({"k" * 2000: 1}), "/", "HGRENDER_MAX_STRING_CHARS"),
        (
            lambda s: s["materials"].update(
                t={
                    "type": "diffuse",
                    "reflectance": {
                        "type": "tabulated",
                        "wavelengths_nm": [400.0 + i * 0.01 for i in range(5000)],
                        "values": [0.5] * 5000,
                    },
                }
            ),
            "/materials/t/reflectance/wavelengths_nm",
            "HGRENDER_MAX_SPECTRUM_SAMPLES",
        ),
    ],
)
def test_every_collection_has_a_limit(
    live_service: LiveService, mutate: Any, pointer: str, variable: str
) -> None:
    scene = tiny_scene()
    mutate(scene)
    response = post_job(live_service, {"scene": scene})
    assert response.status_code == 422
    errors = response.json()["errors"]
    assert any(e["pointer"] in (pointer, pointer.rstrip("/")) and variable in e["message"] for e in errors), (
        errors
    )
    assert all(len(e["message"]) < 200 for e in errors), "an oversized value was echoed"


def test_messages_name_the_configured_limit_and_non_finite_numbers(live_service: LiveService) -> None:
    scene = tiny_scene()
    scene["film"]["width"] = 1_000_000_000
    response = post_job(live_service, {"scene": scene})
    assert response.status_code == 422
    assert response.json()["errors"] == [
        {
            "pointer": "/film/width",
            "message": "width 1000000000 exceeds the limit of 4096 (HGRENDER_MAX_RESOLUTION)",
        }
    ]
    # JSON files may spell NaN and Infinity (Python's json reads them); the message says what they are.
    scene = tiny_scene()
    scene["film"]["wavelength_max_nm"] = float("inf")
    scene["film"]["spp"] = float("nan")
    client = live_service.client()
    response = client.http.post("/v1/jobs", files={"scene": ("s.json", json.dumps(scene, allow_nan=True))})
    assert response.status_code == 422, response.text
    assert response.json()["errors"] == [
        {"pointer": "/film/wavelength_max_nm", "message": "inf is not a finite number"},
        {"pointer": "/film/spp", "message": "nan is not a finite number"},
    ]


def test_artifact_names_and_usd_errors_never_echo_paths(live_service: LiveService) -> None:
    client = live_service.client()
    job_id = client.submit(tiny_scene(), chunks=1)["id"]
    response = client.http.get(f"/v1/jobs/{job_id}/artifacts/..%2F..%2F..%2Fetc%2Fpasswd")
    assert response.status_code == 404
    assert response.json() == {"detail": "name: no such artifact"}
    response = client.http.get(f"/v1/jobs/{job_id}/artifacts/image.exr")  # not rendered: no worker
    assert response.status_code == 404 and response.json() == {"detail": "name: no artifact 'image.exr'"}
    corrupt = b"PXR-USDC" + bytes(range(256)) * 4
    response = client.http.post("/v1/jobs", files={"scene": ("broken.usdc", corrupt)})
    assert response.status_code == 422
    text = response.text
    assert "broken.usdc" in text or "scene.usdc" in text
    for internal in ("/tmp/", "/opt/", ".cpp", "hgrender-upload", "pxrInternal"):
        assert internal not in text, (internal, text)


def test_job_options_are_strict_like_the_scene(live_service: LiveService) -> None:
    before = job_count(live_service)
    for field, value in (("spp", "100"), ("chunks", "4"), ("seed", "1"), ("spp", 2.5), ("spp", True)):
        response = post_job(live_service, {"scene": tiny_scene(), field: value})
        assert response.status_code == 422, (field, value)
        assert response.json()["detail"].startswith(f"{field}:"), response.json()
    assert job_count(live_service) == before
    # Multipart form fields are text by nature: "2" means 2 there.
    client = live_service.client()
    response = client.http.post(
        "/v1/jobs", files={"scene": ("s.json", json.dumps(tiny_scene()))}, data={"spp": "2", "chunks": "2"}
    )
    assert response.status_code == 202
    assert client.get(response.json()["id"])["spp"] == 2


def _five_xx_for_jobs(service: LiveService) -> float:
    metrics = service.get("/metrics", token="").text
    return sum(
        float(line.rsplit(" ", 1)[1])
        for line in metrics.splitlines()
        if line.startswith("hgrender_api_request_duration_seconds_count")
        and 'route="/v1/jobs"' in line
        and 'status="5xx"' in line
    )


def test_a_client_hanging_up_mid_body_is_no_server_error(live_service: LiveService) -> None:
    before = _five_xx_for_jobs(live_service)
    host, port = live_service.base_url.removeprefix("http://").split(":")
    for _ in range(3):
        with socket.create_connection((host, int(port))) as sock:
            sock.sendall(
                b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                b"Authorization: Bearer " + live_service.admin_token.encode() + b"\r\n"
                b"Content-Length: 100000\r\n\r\n" + b'{"scene": {"schema": '
            )
            time.sleep(0.2)
    wait_for(
        lambda: 'status="4xx"' in live_service.get("/metrics", token="").text,
        10,
        "the disconnects to be counted",
    )
    time.sleep(0.5)
    assert _five_xx_for_jobs(live_service) == before


def test_cancel_marks_queued_chunks_canceled(live_service: LiveService) -> None:
    client = live_service.client()
    job_id = client.submit(tiny_scene(), chunks=3)["id"]
    view = client.cancel(job_id)
    assert view["status"] == "canceled"
    assert [c["status"] for c in view["chunks"]] == ["canceled"] * 3


def test_reconciliation_requeues_stranded_and_lost_chunks(live_service: LiveService) -> None:
    """Stranded states a Redis restart or a crash between two steps can leave: a chunk whose RQ job is
    gone, one marked queued in no queue, a merge deferred after its chunks ended. All come back."""
    service = live_service
    jobs = service.jobs
    reconciler = QueueReconciler(jobs.lifecycle, service.settings)
    job_id = service.client().submit(tiny_scene(), chunks=3)["id"]
    assert reconciler.stranded_rq_jobs() == {}
    service.redis.lrem("rq:queue:default", 0, chunk_rq_id(job_id, 1))  # queued, but in no queue
    RQJob.fetch(chunk_rq_id(job_id, 2), connection=service.redis).delete()  # lost altogether
    stranded = reconciler.stranded_rq_jobs()
    assert stranded == {
        chunk_rq_id(job_id, 1): "queued but in no queue or registry",
        chunk_rq_id(job_id, 2): "missing",
    }
    assert reconciler.reconcile(confirm_after_s=0.1) == stranded
    assert reconciler.stranded_rq_jobs() == {}
    queued = [i.decode() for i in service.redis.lrange("rq:queue:default", 0, -1)]
    assert queued[:2] in (
        [chunk_rq_id(job_id, 1), chunk_rq_id(job_id, 2)],
        [chunk_rq_id(job_id, 2), chunk_rq_id(job_id, 1)],
    )
    assert RQJob.fetch(merge_rq_id(job_id), connection=service.redis).get_status() == "deferred"
    jobs.cancel(job_id)
    # A merge still deferred after all its chunks ended (the dependents' enqueue was lost).
    job_id = service.client().submit(tiny_scene(), chunks=2)["id"]
    for index in range(2):
        chunk = RQJob.fetch(chunk_rq_id(job_id, index), connection=service.redis)
        service.redis.lrem("rq:queue:default", 0, chunk.id)
        chunk.set_status("finished")
    assert reconciler.stranded_rq_jobs() == {merge_rq_id(job_id): "deferred after its chunks ended"}
    reconciler.reconcile(confirm_after_s=0.1)
    assert service.redis.lindex("rq:queue:default", 0).decode() == merge_rq_id(job_id)
    assert reconciler.stranded_rq_jobs() == {}
    # The merge itself lost after its chunks ended: recreated and enqueued.
    service.redis.lrem("rq:queue:default", 0, merge_rq_id(job_id))
    RQJob.fetch(merge_rq_id(job_id), connection=service.redis).delete()
    assert reconciler.reconcile(confirm_after_s=0.1) == {merge_rq_id(job_id): "missing"}
    assert service.redis.lindex("rq:queue:default", 0).decode() == merge_rq_id(job_id)
    assert RQJob.fetch(merge_rq_id(job_id), connection=service.redis).func_name == "worker.tasks.merge_task"
    jobs.cancel(job_id)


# ---- through workers ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_merges_run_ahead_of_the_backlog_so_jobs_finish_in_order(live_service: LiveService) -> None:
    service = live_service
    job_ids = service.backlog(5, tiny_scene(size_px=8, spp=2), chunks=2)
    client = service.client()
    service.start_worker("ordered")
    finals = [client.wait(job_id, timeout_s=120) for job_id in job_ids]
    assert all(f["status"] == "succeeded" for f in finals)
    for earlier, later in itertools.pairwise(finals):
        later_chunks_started = min(chunk.started_at for chunk in service.steps(later["id"]).chunks)
        # One worker: job k's merge ran before any chunk of job k + 1 (it used to wait for the whole backlog).
        assert earlier["timings"]["finished_at"] < later_chunks_started
    service.stop_workers()


@pytest.mark.slow
def test_the_scheduler_dies_with_its_worker_and_frees_its_lock(live_service: LiveService) -> None:
    service = live_service
    service.stop_workers()
    worker = service.start_worker("holder")
    lock = RQScheduler.get_locking_key("default")
    holder = wait_for(lambda: service.redis.get(lock), 30, "the worker's scheduler to take the lock")
    scheduler_pid = wait_for(
        lambda: int(service.redis.hget(f"rq:scheduler:{holder.decode()}", "pid") or 0),
        30,
        "the scheduler process to register",
    )
    assert scheduler_pid in children_of(worker.pid)
    os.kill(worker.pid, signal.SIGKILL)  # the worker alone, not its process group
    worker.wait()
    wait_for(
        lambda: not is_alive(scheduler_pid),
        10,
        "the scheduler to exit",
    )
    wait_for(lambda: service.redis.get(lock) != holder, 10, "the scheduler lock to be released")
    service.stop_workers()


@pytest.mark.slow
def test_a_dead_workers_chunk_reruns_within_30_s_with_default_timing(live_service: LiveService) -> None:
    """Default heartbeat settings (5 s beats, 10 s grace, maintenance every 5 s). The victim and its
    scheduler are SIGKILLed together, so the idle survivor must also free the dead scheduler's lock to
    run the delayed retry. A long chunk rendering on a third worker meanwhile (the 2 shared cores are
    busy) is never taken from it."""
    from hgcore.settings import Settings

    service = live_service
    service.stop_workers()
    defaults = Settings()
    timing = {
        "HGRENDER_WORKER_MONITORING_INTERVAL_S": str(defaults.worker_monitoring_interval_s),
        "HGRENDER_WORKER_HEARTBEAT_GRACE_S": str(defaults.worker_heartbeat_grace_s),
        "HGRENDER_WORKER_MAINTENANCE_INTERVAL_S": str(defaults.worker_maintenance_interval_s),
        "HGRENDER_CHUNK_RETRY_INTERVALS_S": json.dumps(defaults.chunk_retry_intervals_s),
    }
    client = service.client()

    def rendering_on(worker: str) -> str:
        job_id = client.submit(tiny_scene(size_px=64, spp=32768), chunks=1)["id"]
        wait_for(
            lambda: (chunk := service.steps(job_id).chunks[0]).worker == worker and chunk.progress > 0,
            60,
            f"{worker} to render",
        )
        return job_id

    victim = service.start_worker("victim", **timing)
    wait_for(lambda: service.redis.get(RQScheduler.get_locking_key("default")), 30, "the victim's scheduler")
    abandoned = rendering_on("victim")
    service.start_worker("busy", **timing)
    long_running = rendering_on("busy")
    service.start_worker("survivor", **timing)
    try:
        _kill_and_measure(service, victim, abandoned, long_running, defaults)
    finally:  # leave no long render to the next test's workers
        client.cancel(abandoned)
        client.cancel(long_running)
        service.stop_workers()


def _kill_and_measure(
    service: LiveService, victim: Any, abandoned: str, long_running: str, defaults: Any
) -> None:
    """SIGKILL the victim (and its horse) rendering ``abandoned``; assert the rerun within 30 s and that
    ``long_running`` keeps its first attempt."""
    horse_pid = service.steps(abandoned).chunks[0].pid
    killed_at = time.time()
    os.killpg(victim.pid, signal.SIGKILL)
    os.kill(horse_pid, signal.SIGKILL)
    victim.wait()
    restarted_at = wait_for(
        lambda: (chunk := service.steps(abandoned).chunks[0]).attempts == 2 and chunk.started_at,
        60,
        "the chunk to rerun",
    )
    recovery_s = restarted_at - killed_at
    print(f"dead-worker recovery: {recovery_s:.1f} s")
    assert recovery_s <= 30.0
    assert service.steps(abandoned).chunks[0].worker == "survivor"
    # No false positive on the live one, also once it has run for longer than the heartbeat TTL (5 + 10 s).
    ttl_s = defaults.worker_monitoring_interval_s + defaults.worker_heartbeat_grace_s
    started_at = service.steps(long_running).chunks[0].started_at
    wait_for(
        lambda: time.time() - started_at > ttl_s + defaults.worker_maintenance_interval_s, 60, "a long run"
    )
    chunk = service.steps(long_running).chunks[0]
    assert chunk.attempts == 1 and chunk.status == "running"


@pytest.mark.slow
def test_cancel_of_a_running_job_leaves_no_chunk_running(live_service: LiveService) -> None:
    service = live_service
    service.stop_workers()
    service.start_worker("c1")
    client = service.client()
    job_id = client.submit(tiny_scene(size_px=64, spp=16384), chunks=2)["id"]
    wait_for(
        lambda: any(c["status"] == "running" for c in client.get(job_id)["chunks"]), 60, "a chunk to run"
    )
    client.cancel(job_id)
    time.sleep(1.5)  # the horse is stopped; nothing may write "running" afterwards
    assert {c["status"] for c in client.get(job_id)["chunks"]} == {"canceled"}
    service.stop_workers()


@pytest.mark.slow
def test_a_worker_waits_for_redis_instead_of_crash_looping(live_service: LiveService, tmp_path: Path) -> None:
    from service.redis_server import RedisServer, free_loopback_port

    port = free_loopback_port()
    worker = live_service.start_worker("patient", REDIS_URL=f"redis://127.0.0.1:{port}/0")
    log = live_service.settings.data_dir / "worker-patient.log"
    try:
        wait_for(
            lambda: log.exists() and log.read_text().count("Redis unavailable") >= 2, 60, "retries logged"
        )
        assert worker.poll() is None  # still the same process: no exit, no restart loop
        with RedisServer(tmp_path / "late-redis", port=port) as late:
            client = redis.Redis.from_url(late.url)
            wait_for(lambda: client.smembers("rq:workers"), 30, "the worker to register once Redis is up")
            client.close()
            live_service.stop_workers()
    finally:
        live_service.stop_workers()


@pytest.mark.slow
def test_a_scheduler_asked_to_stop_without_redis_exits_within_its_deadline(
    live_service: LiveService, tmp_path: Path
) -> None:
    """Its worker dies while Redis is down (``serve`` stops its private Redis right after its workers):
    the scheduler child, told by the kernel (SIGTERM), would retry releasing its locks for the workers'
    whole Redis outage window (30 s); it exits after ``SCHEDULER_STOP_DEADLINE_S`` instead."""
    from service.redis_server import RedisServer
    from worker.queue_worker import SCHEDULER_STOP_DEADLINE_S

    server = RedisServer(tmp_path / "own-redis").start()
    try:
        client = redis.Redis.from_url(server.url)
        worker = live_service.start_worker("stranded", REDIS_URL=server.url)
        lock = RQScheduler.get_locking_key("default")
        holder = wait_for(lambda: client.get(lock), 30, "the scheduler lock")
        scheduler_pid = wait_for(
            lambda: int(client.hget(f"rq:scheduler:{holder.decode()}", "pid") or 0), 30, "the scheduler pid"
        )
        client.close()
        assert server.process is not None
        server.process.kill()
        server.process.wait()
        os.kill(worker.pid, signal.SIGKILL)
        worker.wait()
        stopped_at = time.monotonic()
        wait_for(lambda: not is_alive(scheduler_pid), 30, "the scheduler child to exit")
        assert time.monotonic() - stopped_at <= SCHEDULER_STOP_DEADLINE_S + 2.0
    finally:
        live_service.stop_workers()
        server.stop()
