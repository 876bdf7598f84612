"""End to end through the queue with the real renderer: example scenes over HTTP + SSE, chunk/merge
equivalence, cancel, SIGKILL of a work horse and of a whole worker, and two workers draining 20 jobs.

Scenes are the examples shrunk to 16x16 px and 4 spp (``tiny_scene``); long renders (for cancel and
kills) use more samples so that the render is still running when the test acts.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.jobs.keys import job_key, scene_document_key, steps_key
from hgrender.client import HgrenderClient
from schemas import EXAMPLES_DIR, validate_scene
from tests.support.live_service import LiveService
from tests.support.processes import wait_for
from tests.support.scenes import tiny_scene

pytestmark = pytest.mark.slow


def long_scene(spp: int) -> dict[str, Any]:
    """The Cornell box at 64x64 px with ``spp`` samples: about spp / 700 seconds on 2 shared cores."""
    return tiny_scene(size_px=64, spp=spp)


def wait_until_rendering(client: HgrenderClient, job_id: str, timeout_s: float = 60) -> dict[str, Any]:
    """Wait until some chunk of the job reported progress > 0 (its render loop is running)."""
    return wait_for(
        lambda: (
            (v := client.get(job_id))["status"] == "running"
            and any(c["progress"] > 0 for c in v["chunks"])
            and v
        ),
        timeout_s,
        "the render to start",
    )


@pytest.fixture(scope="module")
def two_workers(live_service: LiveService) -> LiveService:
    live_service.start_worker("w1")
    live_service.start_worker("w2")
    return live_service


def test_example_scenes_end_to_end(two_workers: LiveService, tmp_path: Path) -> None:
    service = two_workers
    client = service.client(service.new_token("eve"))
    names = sorted(p.name for p in EXAMPLES_DIR.glob("*.json"))
    assert names, "no example scenes"
    jobs = {name: client.submit(tiny_scene(name), chunks=2)["id"] for name in names}
    for name, job_id in jobs.items():
        events: list[tuple[str, dict[str, Any]]] = []
        final = client.wait(job_id, on_event=lambda e, d, events=events: events.append((e, d)), timeout_s=120)
        assert final["status"] == "succeeded", (name, final.get("error"))
        assert final["progress"] == 1.0 and final["chunks_done"] == 2
        assert events[0][0] == "status" and events[-1][1]["status"] == "succeeded"
        progress = [d["progress"] for e, d in events if e == "progress"]
        assert progress == sorted(progress) and all(0 <= p <= 1 for p in progress)
        names_listed = {a["name"] for a in client.artifacts(job_id)}
        assert {"image.exr", "preview.png", "summary.json", "worker.log", "manifest.json"} <= names_listed
        out_dir = tmp_path / name
        client.download_all(job_id, out_dir)
        image = read_exr(out_dir / "image.exr")
        channels, pixels = list(image.channels), image.stack()
        spectral = [c for c in channels if c.startswith("S0.") and c.endswith("nm")]
        assert spectral and all("," in c for c in spectral)
        assert {"R", "G", "B", "coherence.l1_um", "coherence.anisotropy"} <= set(channels)
        assert image.attributes["spectralLayoutVersion"] == "1.0"
        assert pixels.shape == (16, 16, len(channels)) and np.isfinite(pixels).all()
        rgb = pixels[..., [channels.index(c) for c in "RGB"]]
        assert rgb.max() > 0, f"{name}: black image"


def test_four_chunk_job_equals_local_split_render(two_workers: LiveService, tmp_path: Path) -> None:
    """The service's 4-chunk merge and ``render_scene(..., chunks=4)`` use the same plan (spp split and
    seeds) and the same arithmetic (each chunk's sums rounded to float32 once, added in float64 in chunk
    order, tile by tile), so their images are bitwise equal."""
    from worker.render.chunks import render_scene

    client = two_workers.client()
    scene = tiny_scene(spp=8)
    job_id = client.submit(scene, chunks=4)["id"]
    final = client.wait(job_id, timeout_s=120)
    assert final["status"] == "succeeded" and final["chunks_total"] == 4
    assert {c["spp"] for c in final["chunks"]} == {2}
    client.download(job_id, "image.exr", tmp_path / "service.exr")
    render_scene(validate_scene(scene), tmp_path / "local", chunks=4)
    service_image, local_image = (
        read_exr(tmp_path / "service.exr"),
        read_exr(tmp_path / "local" / "image.exr"),
    )
    assert list(service_image.channels) == list(local_image.channels)
    np.testing.assert_array_equal(service_image.stack(), local_image.stack())


def test_manifest_lists_artifacts_and_outlives_redis(two_workers: LiveService, tmp_path: Path) -> None:
    import hashlib

    client = two_workers.client()
    job_id = client.submit(tiny_scene(), chunks=2)["id"]
    final = client.wait(job_id, timeout_s=120)
    assert final["status"] == "succeeded"
    manifest_path = client.download(job_id, "manifest.json", tmp_path / "manifest.json")
    manifest = json.loads(manifest_path.read_text())
    assert manifest["job"]["status"] == "succeeded" and manifest["job"]["id"] == job_id
    image = client.download(job_id, "image.exr", tmp_path / "image.exr")
    entry = next(a for a in manifest["artifacts"] if a["name"] == "image.exr")
    assert entry["sha256"] == hashlib.sha256(image.read_bytes()).hexdigest()
    # Lose the job's Redis state: the API answers from the manifest.
    two_workers.redis.delete(job_key(job_id), steps_key(job_id))
    recovered = client.get(job_id)
    assert recovered["status"] == "succeeded" and recovered["timings"] == final["timings"]


def test_cancel_stops_a_running_render_within_5_s(two_workers: LiveService) -> None:
    client = two_workers.client()
    job_id = client.submit(long_scene(spp=32768), chunks=1)["id"]
    wait_until_rendering(client, job_id)
    horse_pid = two_workers.steps(job_id).chunks[0].pid
    canceled_at = time.monotonic()
    assert client.cancel(job_id)["status"] == "canceled"
    wait_for(lambda: not Path(f"/proc/{horse_pid}").exists(), 5.0, "the work horse to stop")
    assert time.monotonic() - canceled_at < 5.0
    time.sleep(1.0)
    view = client.get(job_id)
    assert view["status"] == "canceled"
    assert two_workers.steps(job_id).completions() == {}
    assert not [a for a in client.artifacts(job_id) if a["name"].startswith(("chunks/", "image"))]


def _assert_succeeded_exactly_once(
    service: LiveService, client: HgrenderClient, job_id: str
) -> dict[str, Any]:
    final = client.wait(job_id, timeout_s=120)
    assert final["status"] == "succeeded", final.get("error")
    completions = service.steps(job_id).completions()
    assert completions == {**{str(i): 1 for i in range(final["chunks_total"])}, "merge": 1}
    names = [a["name"] for a in client.artifacts(job_id)]
    assert len(names) == len(set(names))
    # A one-chunk job renders and merges in one work horse: its partial sums never reach the store.
    partials = [f"chunks/{i}.npz" for i in range(final["chunks_total"])] if final["chunks_total"] > 1 else []
    assert sorted(n for n in names if n.startswith("chunks/")) == partials
    assert names.count("image.exr") == 1
    store_root = service.settings.artifact_dir / "jobs" / job_id
    assert not [p for p in store_root.rglob(".*")], "temporary files left behind"
    return final


def test_sigkill_of_the_work_horse_retries_the_chunk(two_workers: LiveService) -> None:
    client = two_workers.client()
    job_id = client.submit(long_scene(spp=2048), chunks=1)["id"]
    wait_until_rendering(client, job_id)
    horse_pid = two_workers.steps(job_id).chunks[0].pid
    os.kill(horse_pid, signal.SIGKILL)
    final = _assert_succeeded_exactly_once(two_workers, client, job_id)
    assert final["chunks"][0]["attempts"] == 2


def test_sigkill_of_a_whole_worker_is_detected_and_retried(live_service: LiveService) -> None:
    """The victim worker and its horse die together; the chunk's heartbeat lapses (1 + 3 s) and the
    surviving worker's maintenance pass (every 2 s) re-queues it."""
    service = live_service
    service.stop_workers()
    service.start_worker("survivor")
    # The survivor holds RQ's scheduler lock (which moves delayed retries back to the queue).
    wait_for(lambda: service.redis.exists("rq:scheduler-lock:default"), 30, "the survivor's scheduler")
    victim = service.start_worker("victim")
    client = service.client()
    # ~6 s a chunk: the victim is still rendering when it is killed after its first heartbeat tick.
    job_id = client.submit(long_scene(spp=8192), chunks=2)["id"]

    def victim_chunk() -> str | None:
        chunks = service.steps(job_id).chunks
        return next((str(i) for i, chunk in enumerate(chunks) if chunk.worker == "victim"), None)

    index = wait_for(victim_chunk, 60, "the victim to take a chunk")
    wait_for(lambda: service.steps(job_id).chunks[int(index)].progress > 0, 60, "victim rendering")
    horse_pid = service.steps(job_id).chunks[int(index)].pid
    time.sleep(1.5)  # past the victim's first heartbeat tick (monitoring interval 1 s) while it is busy
    os.killpg(victim.pid, signal.SIGKILL)  # the worker and its scheduler child
    os.kill(horse_pid, signal.SIGKILL)  # the horse runs in its own process group
    killed_at = time.monotonic()
    victim.wait()
    # The dead worker's key lapses with its chunk's heartbeat (1 + 3 s), not RQ's busy TTL of 61 s: until
    # then it counts as alive and a worker restarted under its name could not start.
    wait_for(
        lambda: not service.redis.exists("rq:worker:victim"), 30, "the dead victim's worker key to lapse"
    )
    assert time.monotonic() - killed_at <= 1 + 3 + 2
    final = _assert_succeeded_exactly_once(service, client, job_id)
    assert final["chunks"][int(index)]["attempts"] == 2
    assert final["chunks"][int(index)]["worker"] == "survivor"
    service.stop_workers()


def _kill_horse_of_attempt(service: LiveService, job_id: str, attempt: int) -> None:
    """Wait until attempt ``attempt`` of the one-chunk job renders, then SIGKILL its work horse."""
    wait_for(
        lambda: (chunk := service.steps(job_id).chunks[0]).attempts == attempt and chunk.progress > 0,
        60,
        f"attempt {attempt} to render",
    )
    os.kill(service.steps(job_id).chunks[0].pid, signal.SIGKILL)


def _one_chunk_job_whose_horses_die(service: LiveService, worker_name: str, attempts: int) -> tuple[Any, str]:
    """A fresh worker ``worker_name`` and a long one-chunk job whose first ``attempts`` horses are killed;
    (the worker's process, the job id)."""
    service.stop_workers()
    worker = service.start_worker(worker_name)
    job_id = service.admin.submit(long_scene(spp=4096), chunks=1)["id"]
    for attempt in range(1, 1 + attempts):
        _kill_horse_of_attempt(service, job_id, attempt)
    return worker, job_id


def test_a_one_chunk_job_whose_horse_dies_on_every_attempt_fails(live_service: LiveService) -> None:
    """The step that renders and merges a one-chunk job cannot report its own death: the worker fails the
    job when the last retry's horse dies, and stays up."""
    service = live_service
    worker, job_id = _one_chunk_job_whose_horses_die(service, "k1", 1 + service.settings.chunk_retry_max)
    client = service.client()
    final = client.wait(job_id, timeout_s=60)
    assert final["status"] == "failed"
    assert final["error"].startswith(f"render and merge job {job_id}: Work-horse terminated unexpectedly")
    assert final["chunks"][0]["attempts"] == 1 + service.settings.chunk_retry_max
    assert "manifest.json" in {a["name"] for a in client.artifacts(job_id)}
    assert worker.poll() is None
    service.stop_workers()


def test_a_one_chunk_job_whose_worker_dies_on_the_last_attempt_fails(live_service: LiveService) -> None:
    """Horses killed on the first attempts, then the whole worker on the last: another worker's maintenance
    pass finds the abandoned step (heartbeat 1 + 3 s) and fails the job instead of leaving it running."""
    service = live_service
    victim, job_id = _one_chunk_job_whose_horses_die(service, "victim", service.settings.chunk_retry_max)
    client = service.client()
    last = 1 + service.settings.chunk_retry_max
    wait_for(lambda: service.steps(job_id).chunks[0].attempts == last, 60, "the last attempt")
    horse_pid = service.steps(job_id).chunks[0].pid
    os.killpg(victim.pid, signal.SIGKILL)
    os.kill(horse_pid, signal.SIGKILL)
    victim.wait()
    service.start_worker("survivor")
    final = client.wait(job_id, timeout_s=60)
    assert final["status"] == "failed"
    assert (
        final["error"]
        == f"render and merge job {job_id}: its worker died (heartbeat lapsed) on the last attempt"
    )
    service.stop_workers()


def test_two_workers_drain_20_jobs_without_running_any_twice(live_service: LiveService) -> None:
    service = live_service
    job_ids = service.backlog(20, tiny_scene(size_px=8, spp=1), chunks=1)
    client = service.client()
    service.start_worker("d1")
    service.start_worker("d2")
    for job_id in job_ids:
        assert client.wait(job_id, timeout_s=120)["status"] == "succeeded"
        steps = service.steps(job_id)
        assert steps.completions() == {"0": 1, "merge": 1}
        assert steps.chunks[0].attempts == 1
    workers = {w for job_id in job_ids for w in client.get(job_id)["workers"]}
    assert workers == {"d1", "d2"}
    service.stop_workers()


def test_multipart_uploads_of_json_and_usd_render(two_workers: LiveService, tmp_path: Path) -> None:
    """A scene uploaded as a .json file and as a USD layer (exported from the same scene) both render;
    the USD import keeps the film, so the job's spp is the scene's."""
    from schemas import validate_scene
    from schemas.usd_export import scene_to_usd

    if not two_workers.workers:
        two_workers.start_worker("w-upload")
    client = two_workers.client()
    scene = tiny_scene()
    json_path = tmp_path / "scene.json"
    json_path.write_text(json.dumps(scene))
    usd_path = scene_to_usd(validate_scene(scene), tmp_path / "scene.usda")
    for path in (json_path, usd_path):
        job_id = client.submit(path, chunks=1, priority="high")["id"]
        final = client.wait(job_id, timeout_s=120)
        assert final["status"] == "succeeded", (path.name, final.get("error"))
        assert final["spp"] == scene["film"]["spp"] and final["priority"] == "high"
    bad = tmp_path / "scene.txt"
    bad.write_text("nope")
    response = client.http.post("/v1/jobs", files={"scene": (bad.name, bad.read_bytes())})
    assert response.status_code == 422 and response.json()["detail"].startswith("scene:")


def test_a_chunk_failing_every_retry_fails_the_job_with_its_error(live_service: LiveService) -> None:
    """Losing the scene makes every attempt of the chunk raise; after the retries (1 s apart here) the
    merge step reports the chunk's error and the job reads ``failed``."""
    service = live_service
    service.stop_workers()
    client = service.client()
    job_id = client.submit(tiny_scene(), chunks=1)["id"]
    service.redis.delete(scene_document_key(job_id))
    service.start_worker("f1")
    final = client.wait(job_id, timeout_s=120)
    assert final["status"] == "failed"
    assert final["error"].startswith("chunk 0:") and job_id in final["error"]
    assert final["chunks"][0]["attempts"] == 1 + service.settings.chunk_retry_max
    names = {a["name"] for a in client.artifacts(job_id)}
    assert {"worker.log", "manifest.json"} <= names and "image.exr" not in names
    service.stop_workers()


def test_a_worker_killed_while_cleaning_blocks_recovery_for_seconds_not_minutes(
    live_service: LiveService,
) -> None:
    """RQ's registry-cleaning lock lives 899 s: a worker SIGKILLed inside its maintenance pass (found in CI:
    a test's teardown killed one there) left every worker unable to detect abandoned chunks on that queue
    for 15 minutes. The render worker's queues take it for MAINTENANCE_LOCK_TTL_S."""
    from rq import Queue

    from hgcore.settings import QUEUE_NAMES
    from worker.queue_worker import MAINTENANCE_LOCK_TTL_S, RenderQueue, build_worker

    worker = build_worker(live_service.settings, live_service.redis, name="lock-probe")
    assert [type(queue) for queue in worker.queues] == [RenderQueue] * len(QUEUE_NAMES)
    queue = worker.queues[0]
    live_service.redis.delete(queue.registry_cleaning_key)
    try:
        assert queue.acquire_maintenance_lock()
        assert 0 < live_service.redis.ttl(queue.registry_cleaning_key) <= MAINTENANCE_LOCK_TTL_S <= 60
        assert not queue.acquire_maintenance_lock()  # still exclusive while it lives
        queue.release_maintenance_lock()
        plain = Queue(queue.name, connection=live_service.redis)
        assert plain.acquire_maintenance_lock()
        assert live_service.redis.ttl(plain.registry_cleaning_key) > 60  # what RQ alone would leave behind
    finally:
        live_service.redis.delete(queue.registry_cleaning_key)


def test_a_stop_right_after_the_fork_cannot_reach_the_worker_s_group(
    live_service: LiveService, monkeypatch: pytest.MonkeyPatch
) -> None:
    """RQ's horse puts itself in its own process group (``setpgrp``) after the fork; a cancel that came
    first made ``kill_horse``'s ``killpg(getpgid(horse))`` kill the worker's group (the worker died and
    every job queued after it waited for ever; CI). The worker's fork sets the horse's group from the
    parent too: here the horse never calls ``setpgrp`` (patched out, as if it had not run yet), and its
    group is still its own, not the worker's (the test process's)."""
    from types import SimpleNamespace

    from worker.queue_worker import RenderWorker, build_worker

    worker = build_worker(live_service.settings, live_service.redis, name="fork-probe")
    monkeypatch.setenv("RQ_WORKER_ID", "unset")  # RQ's fork writes both; monkeypatch restores them
    monkeypatch.setenv("RQ_JOB_ID", "unset")
    monkeypatch.setattr(os, "setpgrp", lambda: None)
    monkeypatch.setattr(RenderWorker, "main_work_horse", lambda self, job, queue: time.sleep(30))
    worker.fork_work_horse(SimpleNamespace(id="fork-probe-job"), None)
    horse = worker.horse_pid
    try:
        assert os.getpgid(horse) == horse != os.getpgrp()
    finally:
        os.kill(horse, signal.SIGKILL)
        os.waitpid(horse, 0)


def test_handing_back_a_deleted_job_does_not_kill_the_worker(live_service: LiveService) -> None:
    """Canceling a running chunk and deleting its job at once (the viewer's job list does both): RQ fails
    to enqueue the dependents of the deleted job and quits its loop; the worker's recovery then handed the
    chunk back, whose status read raised for the missing job and killed the worker, so every later job
    stayed queued (a fresh-clone CI run). A deleted job has nothing to hand back."""
    from rq import Queue
    from rq.job import Job

    from worker.queue_worker import build_worker

    worker = build_worker(live_service.settings, live_service.redis, name="hand-back-probe")
    queue = Queue("low", connection=live_service.redis)
    job = Job.create(func="builtins.print", connection=live_service.redis, origin=queue.name)
    job.save()
    job.delete()
    worker.hand_back(job, queue, None)  # raised rq.exceptions.InvalidJobOperation before
    assert queue.count == 0
