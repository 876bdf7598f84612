"""RQ job functions: render one chunk of a job, merge a job's chunks into its final artifacts, or do both
for a job of one chunk; and fail a job whose final step failed for good.

They run in RQ's forked work horse (``worker.queue_worker``), so the renderer (Mitsuba, Dr.Jit) is
imported here and never in the API process. A chunk renders spp partition ``i`` of
``worker.render.api.plan_chunks(spp, K, seed)`` and uploads ``jobs/<id>/chunks/<i>.npz`` to the artifact
store; a retried chunk uploads to the same key, so a retry never leaves a duplicate. The merge step runs
after every chunk ended (success or failure) and writes ``image.exr``, ``preview.png``,
``summary.json`` (and whatever else ``merge_chunks`` produces), ``worker.log`` and ``manifest.json``.
A one-chunk job runs both in one work horse and keeps its partial sums local.
"""

from __future__ import annotations

import atexit
import ctypes
import functools
import gc
import hashlib
import json
import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from rq import get_current_job
from rq.exceptions import NoSuchJobError
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from hgcore import noise_target
from hgcore.artifacts.keys import (
    artifact_key,
    chunk_key,
    chunks_prefix,
    input_prefix,
    job_prefix,
    manifest_key,
    scene_key,
    worker_log_key,
)
from hgcore.artifacts.pixel_sums import write_partial_rows
from hgcore.artifacts.running_sums import RunningSums
from hgcore.jobs.keys import job_key
from hgcore.jobs.queue_graph import chunk_rq_id
from hgcore.jobs.records import JobRecords
from hgcore.jobs.status import TERMINAL_STATUSES, JobStatus
from hgcore.noise_target import ImageErrors, NoiseTarget
from hgcore.settings import Settings
from hgcore.store import store_from_settings
from schemas import EXAMPLES_DIR, validate_scene
from schemas.scene import MAX_FILM_MODES, Scene
from worker.queue_worker import HORSE_TEMP_PREFIX

CANCEL_POLL_INTERVAL_S = 0.5
"""How often a running chunk re-reads its job's status (a cancel stops it within this plus one pass)."""


def horse_work_dir(label: str) -> tempfile.TemporaryDirectory[str]:
    """A temporary folder for one step, named after this work horse's pid
    (``worker.queue_worker.HORSE_TEMP_PREFIX``): when the horse is killed before it could clean up, its
    worker removes what it left (``remove_horse_temp_dirs``)."""
    return tempfile.TemporaryDirectory(prefix=f"{HORSE_TEMP_PREFIX.format(pid=os.getpid())}{label}-")


def preload_renderer() -> None:
    """Load, in the worker's main process, what every forked work horse would otherwise load again for
    each job: the renderer's modules and Mitsuba's plugins, the image writers, data tables and caches
    (together ~1 s for a horse's first chunk, and still ~30 ms per job once the modules are imported).
    No Dr.Jit backend is initialised here: its LLVM thread pool or CUDA context would not survive the
    fork. Then the collector is told to leave the loaded objects alone."""
    _load_libraries()
    _fill_caches()
    # Objects that exist now are left alone by the collector, so a horse's garbage collections do not
    # copy the worker's memory pages (copy-on-write) that it would otherwise only read. Unfrozen at exit,
    # so that the interpreter's last collection still finalises them.
    gc.freeze()
    atexit.register(gc.unfreeze)


def _load_libraries() -> None:
    from worker.mitsuba_setup import point_drjit_at_libllvm

    point_drjit_at_libllvm()
    import mitsuba
    import OpenImageIO  # noqa: F401  (EXR writing, imported lazily by the merge step)
    import PIL.Image  # (preview PNG, idem)

    PIL.Image.init()  # registers the image plugins now, not at the first save in each horse (~20 ms)

    import worker.render.api  # noqa: F401
    from hgcore.artifacts.images import preview_png

    preview_png(np.zeros((1, 1, 3)))  # PIL's first PNG encoding (~2 ms); zlib starts no threads
    # Not so OpenImageIO: its first image output starts a thread pool that a forked horse would lack
    # (the horse's EXR writes then hang), so its ~2 ms first-use cost stays in each horse.

    # Mitsuba loads each plugin (a shared library: shapes, emitters, films, ...) on its first use in a
    # process. Loaded here, every horse finds them resident (~10 ms per job); loading starts no threads.
    for plugin in sorted((Path(mitsuba.__file__).parent / "plugins").glob("*.so")):
        ctypes.CDLL(str(plugin))


def _fill_caches() -> None:
    from hgcore.optics import ior, spectra
    from hgcore.optics.sources import open_cylinder_coefficient_table, source_coefficients

    # The renderer's disk and rectangle source expansions (~3 ms each) and the open cylinder's mode tables
    # (one exact-integration pass over the obliquities, ~0.9 s, then ~5 ms per mode count).
    for modes in range(1, MAX_FILM_MODES + 1):
        source_coefficients("disk", modes)
        source_coefficients("rect", modes)
        open_cylinder_coefficient_table(modes)
    # Data tables: CIE colour matching functions, illuminants, metals' refractive indices.
    spectra.cie_cmf(550.0)
    for illuminant in spectra.ILLUMINANTS:
        spectra.cie_illuminant(illuminant, 550.0)
    for metal in ior.METALS:
        ior.metal_table(metal)
    # The first validation in a process fills pydantic's and abc's caches (~5 ms).
    for example in sorted(EXAMPLES_DIR.glob("*.json")):
        validate_scene(json.loads(example.read_text()))
    task_settings()


@functools.cache
def task_settings() -> Settings:
    """The worker's settings (its environment), read once per worker process and inherited by horses."""
    return Settings()


def _context() -> tuple[JobRecords, RQJob]:
    rq_job = get_current_job()
    if rq_job is None:
        raise RuntimeError("worker.tasks functions run inside an RQ work horse (hgrender worker)")
    settings = task_settings()
    return JobRecords(rq_job.connection, store_from_settings(settings), settings), rq_job


class _ProgressReporter:
    """Forwards a chunk's progress to Redis, at most once per ``interval_s``."""

    def __init__(self, jobs: JobRecords, job_id: str, index: int, interval_s: float) -> None:
        self.jobs, self.job_id, self.index, self.interval_s = jobs, job_id, index, interval_s
        self._last_s = 0.0

    def __call__(self, fraction: float) -> None:
        now = time.monotonic()
        if now - self._last_s >= self.interval_s:
            self._last_s = now
            self.jobs.chunk_progress(self.job_id, self.index, fraction)


class _CancelPoll:
    """``should_stop`` for the renderer: True once the job was canceled or deleted."""

    def __init__(self, jobs: JobRecords, job_id: str) -> None:
        self.jobs, self.job_id = jobs, job_id
        self._last_s = 0.0
        self._stop = False

    def __call__(self, force: bool = False) -> bool:
        now = time.monotonic()
        if not self._stop and (force or now - self._last_s >= CANCEL_POLL_INTERVAL_S):
            self._last_s = now
            self._stop = self.jobs.status(self.job_id) in {JobStatus.CANCELED, None}
        return self._stop


def _load_inputs(jobs: JobRecords, job_id: str, work_dir: Path) -> tuple[dict[str, Any], Path | None]:
    """The job's scene and, for an uploaded bundle, the local folder its files were copied to (the
    renderer resolves the scene's relative file paths against it)."""
    inputs_prefix = input_prefix(job_id)
    bundle_dir = work_dir / "input"
    inputs = jobs.store.list(inputs_prefix)
    for info in inputs:
        jobs.store.get_file(info.key, bundle_dir / info.key.removeprefix(inputs_prefix))
    return jobs.scene(job_id), bundle_dir if inputs else None


def _skipped(record: dict[str, str]) -> dict[str, Any] | None:
    """The task's result when its job is gone or already ended (nothing left to do), else None."""
    if not record or JobStatus(record["status"]) in TERMINAL_STATUSES:
        return {"skipped": record.get("status", "deleted")}
    return None


class StepFailedError(RuntimeError):
    """An error of one step of a job, its message prefixed with the step (``chunk 0: …``, ``merge: …``)."""


@contextmanager
def _step(name: str) -> Iterator[None]:
    """Label any error raised inside with the step ``name`` (the job's error names where it failed)."""
    try:
        yield
    except StepFailedError:
        raise
    except Exception as error:
        raise StepFailedError(f"{name}: {type(error).__name__}: {error}") from error


def _chunk_spec(record: dict[str, str], chunk_index: int) -> Any:
    from worker.render.api import plan_chunks

    return plan_chunks(int(record["spp"]), int(record["chunks"]), int(record["seed"]))[chunk_index]


def _started(
    jobs: JobRecords, rq_job: RQJob, job_id: str, record: dict[str, str], chunk_index: int, work_dir: Path
) -> tuple[Any, Scene, Path | None, _CancelPoll]:
    """Mark chunk ``chunk_index`` running; its spec, the validated scene, the bundle folder (inputs copied
    to ``work_dir``) and the cancel poll."""
    from worker.render.api import as_scene

    chunk = _chunk_spec(record, chunk_index)
    jobs.chunk_started(job_id, chunk_index, rq_job.worker_name or "", os.getpid(), chunk.spp)
    scene_document, bundle_dir = _load_inputs(jobs, job_id, work_dir)
    return chunk, as_scene(scene_document), bundle_dir, _CancelPoll(jobs, job_id)


def _progress(jobs: JobRecords, job_id: str, chunk_index: int) -> _ProgressReporter:
    return _ProgressReporter(jobs, job_id, chunk_index, jobs.settings.progress_interval_s)


def render_chunk_task(job_id: str, chunk_index: int) -> dict[str, Any]:
    """Render chunk ``chunk_index`` of job ``job_id`` and upload its partial (streamed tile by tile)."""
    jobs, rq_job = _context()
    record = jobs.record(job_id)
    if (skipped := _skipped(record)) is not None:
        return skipped
    from worker.render.api import render_chunk
    from worker.render.renderer import RenderCanceledError

    with horse_work_dir(f"{job_id}-{chunk_index}") as tmp:
        chunk, scene, bundle_dir, should_stop = _started(jobs, rq_job, job_id, record, chunk_index, Path(tmp))
        partial_path = Path(tmp) / f"chunk-{chunk_index}.npz"
        try:
            result = render_chunk(
                scene,
                chunk,
                partial_path,
                progress=_progress(jobs, job_id, chunk_index),
                should_stop=should_stop,
                bundle_dir=bundle_dir,
            )
        except RenderCanceledError:
            result = None
        if result is None or should_stop(force=True):
            jobs.set_chunk_status(job_id, chunk_index, "canceled")
            return {"canceled": True}
        jobs.store.put_file(chunk_key(job_id, chunk_index), partial_path)
    jobs.chunk_finished(job_id, chunk_index, result["samples"], result["seconds"])
    return {"samples": result["samples"], "seconds": result["seconds"]}


PREVIEW_OVERHEAD_RATIO = 10.0
"""A noise-target job publishes a round's preview when it rendered at least this many times the last
publication's cost since then: previews add at most the first one's cost plus 1/10 to the render."""


class _RoundPreviews:
    """``on_round`` of a noise-target job: after a round that another follows, publish the image of the
    rounds so far where a multi-chunk job's finished chunks are, as chunk 0's partial
    (``jobs/<id>/chunks/0.npz``: a target job is one chunk; atomic, replaced round by round, so the
    viewer's merge of the chunk partials shows it), then record the block of the rounds so far in the
    job view (``JobRecords.noise_target_round``; the viewer refreshes when its round count changes).
    The partial is streamed row band by row band (one tile's float32 table at a time) from the running
    sums the render keeps on disk anyway; the final artifacts are written from the same sums as before.

    Publishing costs time that grows with the image (at 1024² × 32 bands: a 368 MiB partial written and
    stored, and the per-band errors, ≈ 3–5 s on 2 cores), while a round near the target can be short
    (the next round adds at least N/16 spp). So the first round is always published (the viewer has an
    image early) and a later one only once the render time since the last publication is at least
    ``PREVIEW_OVERHEAD_RATIO`` times that publication's cost; small images publish every round."""

    def __init__(self, jobs: JobRecords, job_id: str, target: NoiseTarget, seed: int, work_dir: Path) -> None:
        self.jobs, self.job_id, self.target, self.seed = jobs, job_id, target, seed
        self.path = work_dir / "round-preview.npz"
        self.published_at_render_s: float | None = None  # render seconds at the last publication
        self.cost_s = 0.0  # what the last publication took (wall seconds)

    def __call__(self, running: RunningSums, errors: ImageErrors, rounds: list[dict[str, Any]]) -> None:
        render_s = rounds[-1]["seconds"]
        if (
            self.published_at_render_s is not None
            and render_s - self.published_at_render_s < PREVIEW_OVERHEAD_RATIO * self.cost_s
        ):
            return
        started = time.perf_counter()
        self._publish(running, errors, rounds)
        self.published_at_render_s, self.cost_s = render_s, time.perf_counter() - started

    def _publish(self, running: RunningSums, errors: ImageErrors, rounds: list[dict[str, Any]]) -> None:
        from worker.render.renderer import tile_bands

        width, height = running.width, running.height
        row_bands = running.row_bands(tile_bands(width, height))
        write_partial_rows(
            self.path,
            width,
            height,
            running.band_count,
            row_bands,
            running.sample_count,
            rounds[-1]["seconds"],
            0,
            self.seed,
        )
        self.jobs.store.put_file(chunk_key(self.job_id, 0), self.path)
        block = noise_target.summary_block(self.target, errors, rounds, None)
        self.jobs.noise_target_round(self.job_id, block)


def render_job_task(job_id: str) -> dict[str, Any]:
    """Render a job of one chunk (or a noise-target job, which adds rounds in this horse) and write its
    final artifacts, streamed tile by tile, in one work horse. A failure on the last attempt fails the
    job with the step's error."""
    jobs, rq_job = _context()
    try:
        record = jobs.record(job_id)
        if (skipped := _skipped(record)) is not None:
            return skipped
        from worker.render.api import render_to_dir
        from worker.render.renderer import RenderCanceledError

        with horse_work_dir(job_id) as tmp:
            work_dir = Path(tmp)
            out_dir = work_dir / "out"
            with _step("chunk 0"):
                chunk, scene, bundle_dir, should_stop = _started(jobs, rq_job, job_id, record, 0, work_dir)
                target = NoiseTarget.from_record(record)
                previews = (
                    None if target is None else _RoundPreviews(jobs, job_id, target, chunk.seed, work_dir)
                )
                try:
                    summary = render_to_dir(
                        scene,
                        out_dir,
                        [chunk],
                        progress=_progress(jobs, job_id, 0),
                        should_stop=should_stop,
                        bundle_dir=bundle_dir,
                        target=target,
                        on_round=previews,
                        extra_summary={"job_id": job_id},
                    )
                except RenderCanceledError:
                    summary = None
            if summary is None or should_stop(force=True):
                jobs.set_chunk_status(job_id, 0, "canceled")
                return {"canceled": True}
            jobs.chunk_finished(job_id, 0, summary["samples"], summary["render_seconds"])
            with _step("merge"):
                started_s = _merge_started(jobs, rq_job, job_id)
                return _write_final_artifacts(jobs, job_id, out_dir, summary, started_s)
    except StepFailedError as error:
        _fail_on_last_attempt(jobs, rq_job, job_id, str(error))
        raise


def _chunk_failures(jobs: JobRecords, job_id: str, chunk_count: int) -> list[str]:
    """One line per chunk that did not finish: its index and last error."""
    failures = []
    for index in range(chunk_count):
        try:
            rq_job = RQJob.fetch(chunk_rq_id(job_id, index), connection=jobs.client)
        except NoSuchJobError:
            failures.append(f"chunk {index}: lost from the queue")
            continue
        if rq_job.get_status() != RQJobStatus.FINISHED:
            result = rq_job.latest_result()
            reason = (result.exc_string or "").strip().splitlines()[-1:] if result else []
            failures.append(f"chunk {index}: {reason[0] if reason else rq_job.get_status()}")
    return failures


def _worker_log(jobs: JobRecords, job_id: str) -> bytes:
    """A plain-text log of who rendered what, in how many attempts and how long."""
    view = jobs.get(job_id)
    assert view is not None
    lines = [f"job {job_id} owner={view.owner} spp={view.spp} seed={view.seed} chunks={view.chunks_total}"]
    lines += [
        f"chunk {c.index}: status={c.status} worker={c.worker} attempts={c.attempts} spp={c.spp} "
        f"samples={c.samples} seconds={c.seconds}"
        for c in view.chunks
    ]
    return ("\n".join(lines) + "\n").encode()


def _artifact_digests(jobs: JobRecords, job_id: str) -> list[dict[str, Any]]:
    """Name, size and SHA-256 of every stored artifact of the job (streamed, never all in memory)."""
    digests = []
    for info in jobs.store.list(job_prefix(job_id)):
        if info.key == manifest_key(job_id):
            continue
        sha256 = hashlib.sha256()
        for piece in jobs.store.iter_bytes(info.key):
            sha256.update(piece)
        name = info.key.removeprefix(job_prefix(job_id))
        digests.append({"name": name, "size_bytes": info.size_bytes, "sha256": sha256.hexdigest()})
    return digests


def _write_manifest(
    jobs: JobRecords,
    job_id: str,
    artifacts: list[dict[str, Any]],
    overrides: dict[str, Any],
    **timing_overrides: float,
) -> None:
    """``manifest.json``: the job's final view and every artifact's size and SHA-256, so results outlive
    the loss of Redis (``JobRecords.get`` falls back to it). ``overrides`` replace view fields and
    ``timing_overrides`` timing fields (the final values, written before the status changes)."""
    view = jobs.get(job_id)
    assert view is not None
    job = view.model_dump(mode="json") | overrides
    job["timings"] |= timing_overrides
    manifest = {"job": job, "artifacts": artifacts, "written_at": time.time()}
    jobs.store.put_bytes(manifest_key(job_id), json.dumps(manifest, indent=1).encode())


def _fail(jobs: JobRecords, job_id: str, error: str) -> None:
    """Record a failed job: its log and manifest first, then the final status."""
    finished_at = time.time()
    jobs.store.put_bytes(worker_log_key(job_id), _worker_log(jobs, job_id) + f"error: {error}\n".encode())
    created_at = float(jobs.record(job_id)["created_at"])
    artifacts = _artifact_digests(jobs, job_id)
    final = {"status": "failed", "error": error, "eta_s": None}
    _write_manifest(jobs, job_id, artifacts, final, finished_at=finished_at, total_s=finished_at - created_at)
    if jobs.transition(job_id, JobStatus.FAILED, error=error, finished_at=repr(finished_at)) is None:
        _write_manifest(jobs, job_id, artifacts, {})  # canceled meanwhile


def _fail_on_last_attempt(jobs: JobRecords, rq_job: RQJob, job_id: str, error: str) -> None:
    """Fail the job when this attempt of its final step was the last (RQ retries the others)."""
    if not rq_job.retries_left:
        fail_job(jobs, job_id, error)


def fail_job(jobs: JobRecords, job_id: str, error: str) -> None:
    """Fail the job unless it already ended (it may have been canceled or deleted meanwhile). Also called
    by the worker when a final step's work horse died on its last attempt (``worker.queue_worker``)."""
    if jobs.status(job_id) not in {*TERMINAL_STATUSES, None}:
        _fail(jobs, job_id, error)


def merge_task(job_id: str) -> dict[str, Any]:
    """Merge the chunks of ``job_id`` into the final artifacts, or fail the job if a chunk failed. An
    error in the merge itself is retried like a chunk's; the last attempt fails the job with it."""
    jobs, rq_job = _context()
    try:
        record = jobs.record(job_id)
        if (skipped := _skipped(record)) is not None:
            return skipped
        chunk_count = int(record["chunks"])
        failures = _chunk_failures(jobs, job_id, chunk_count)
        if failures:
            _fail(jobs, job_id, "; ".join(failures))
            return {"failed": failures}
        with _step("merge"), horse_work_dir(f"{job_id}-merge") as tmp:
            from worker.render.api import merge_chunks

            started_s = _merge_started(jobs, rq_job, job_id)
            work_dir = Path(tmp)
            chunk_paths = [work_dir / "chunks" / f"{index}.npz" for index in range(chunk_count)]
            for index, path in enumerate(chunk_paths):
                jobs.store.get_file(chunk_key(job_id, index), path)
            out_dir = work_dir / "out"
            summary = merge_chunks(jobs.scene(job_id), chunk_paths, out_dir, extra_summary={"job_id": job_id})
            return _write_final_artifacts(jobs, job_id, out_dir, summary, started_s)
    except StepFailedError as error:
        _fail_on_last_attempt(jobs, rq_job, job_id, str(error))
        raise


def _merge_started(jobs: JobRecords, rq_job: RQJob, job_id: str) -> float:
    """Record the merge step as running; its start on the monotonic clock (seconds)."""
    jobs.chunk_started(job_id, "merge", rq_job.worker_name or "", os.getpid())
    return time.monotonic()


def _write_final_artifacts(
    jobs: JobRecords, job_id: str, out_dir: Path, summary: dict[str, Any], started_s: float
) -> dict[str, Any]:
    """Upload the job's artifacts written to ``out_dir`` (``summary``: its summary.json), then its log,
    scene and manifest, and mark it succeeded (the merge step's bookkeeping is ``merge.<field>``, timed
    from ``started_s``). A noise-target job's achieved error goes into its record (the job view)."""
    scene_document = jobs.scene(job_id)
    if "noise_target" in summary:
        jobs.client.hset(job_key(job_id), "noise_target", json.dumps(summary["noise_target"]))
    for path in sorted(out_dir.rglob("*")):
        if path.is_file():
            jobs.store.put_file(artifact_key(job_id, path.relative_to(out_dir).as_posix()), path)
    if "noise_target" in summary:
        # The rounds' preview (``_RoundPreviews``) is superseded by image.exr: a target job's artifacts
        # and manifest are what they were without previews.
        jobs.store.delete_prefix(chunks_prefix(job_id))
    merge_s = time.monotonic() - started_s
    jobs.chunk_finished(job_id, "merge", samples=0, seconds=merge_s)
    jobs.store.put_bytes(worker_log_key(job_id), _worker_log(jobs, job_id))
    jobs.store.put_bytes(scene_key(job_id), json.dumps(scene_document, indent=1).encode())  # provenance
    finished_at = time.time()
    # The manifest is complete before the status says succeeded, so a client never misses or races it.
    created_at = float(jobs.record(job_id)["created_at"])
    final = {"status": "succeeded", "progress": 1.0, "eta_s": None}
    artifacts = _artifact_digests(jobs, job_id)
    _write_manifest(jobs, job_id, artifacts, final, finished_at=finished_at, total_s=finished_at - created_at)
    if jobs.transition(job_id, JobStatus.SUCCEEDED, finished_at=repr(finished_at)) is None:
        _write_manifest(jobs, job_id, artifacts, {})  # a cancel won the race: the manifest says so
    return {"summary": summary, "merge_s": merge_s}
