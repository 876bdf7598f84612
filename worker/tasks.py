"""RQ job functions: render one chunk of a job, merge a job's chunks into its final artifacts, or do both
for a job of one chunk; and evaluate a regression run once its renders ended.

They run in RQ's forked work horse (``worker.queue_worker``) with the settings their worker bound
(``worker.horse``), so the renderer (Mitsuba, Dr.Jit) is imported here and never in the API process. Every
change to a job goes through its ``JobLifecycle``: a chunk renders spp partition ``i`` of
``worker.render.chunks.plan_chunks(spp, K, seed)`` and uploads ``jobs/<id>/chunks/<i>.npz`` to the artifact
store (a retried chunk uploads to the same key, so a retry never leaves a duplicate); the merge step runs
after every chunk ended (success or failure) and ``finalize`` stores ``image.exr``, ``preview.png``,
``summary.json`` (and whatever else ``merge_chunks`` produces), ``worker.log`` and ``manifest.json``.
A one-chunk job runs both in one work horse and keeps its partial sums local.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rq import get_current_job
from rq.job import Job as RQJob

from hgcore.artifacts.keys import chunk_key, input_prefix
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.queue_graph import chunk_failures
from hgcore.jobs.record import MERGE_STEP, JobRecord
from hgcore.regression.evaluation import RunEvaluator
from hgcore.settings import Settings
from hgcore.store import store_from_settings
from schemas import Scene, validate_scene
from worker.horse import bound_settings, horse_work_dir
from worker.step_monitor import CancelPoll, ProgressReporter, RoundPreviews


@dataclass(frozen=True)
class _Horse:
    """What a task runs with: its job's lifecycle, its RQ job and the worker's settings."""

    lifecycle: JobLifecycle
    rq_job: RQJob
    settings: Settings

    @classmethod
    def current(cls) -> _Horse:
        rq_job = get_current_job()
        if rq_job is None:
            raise RuntimeError("worker.tasks functions run inside an RQ work horse (hgrender worker)")
        settings = bound_settings()
        return cls(JobLifecycle(rq_job.connection, store_from_settings(settings)), rq_job, settings)

    @property
    def worker_name(self) -> str:
        return self.rq_job.worker_name or ""

    def progress(self, job_id: str, chunk_index: int) -> ProgressReporter:
        return ProgressReporter(self.lifecycle, job_id, chunk_index, self.settings.progress_interval_s)


def _skipped(record: JobRecord | None) -> dict[str, Any]:
    """The task's result when its job is gone (None) or already ended: nothing is left to do."""
    return {"skipped": record.status.value if record is not None else "deleted"}


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


def _fail_on_last_attempt(horse: _Horse, job_id: str, error: str) -> None:
    """Fail the job when this attempt of its final step was the last (RQ retries the others)."""
    if not horse.rq_job.retries_left:
        horse.lifecycle.fail(job_id, error)


def _scene(horse: _Horse, job_id: str) -> Scene:
    """The job's scene, validated against this worker's limits (the API's may differ) into the typed
    model every step then passes on."""
    return validate_scene(horse.lifecycle.scene(job_id), horse.settings)


def _inputs(horse: _Horse, job_id: str, work_dir: Path) -> tuple[Scene, Path | None]:
    """The job's scene and, for an uploaded bundle, the local folder its files were copied to (the
    renderer resolves the scene's relative file paths against it)."""
    store = horse.lifecycle.store
    inputs_prefix = input_prefix(job_id)
    bundle_dir = work_dir / "input"
    inputs = store.list(inputs_prefix)
    for info in inputs:
        store.get_file(info.key, bundle_dir / info.key.removeprefix(inputs_prefix))
    return _scene(horse, job_id), bundle_dir if inputs else None


def _start_chunk(
    horse: _Horse, record: JobRecord, chunk_index: int, work_dir: Path
) -> tuple[Any, Scene, Path | None, CancelPoll]:
    """Mark chunk ``chunk_index`` running; its spec, the scene, the bundle folder (inputs copied to
    ``work_dir``) and the cancel poll."""
    from worker.render.chunks import plan_chunks

    chunk = plan_chunks(record.spp, record.chunk_count, record.seed)[chunk_index]
    horse.lifecycle.start_chunk(record.id, chunk_index, horse.worker_name, os.getpid(), chunk.spp)
    scene, bundle_dir = _inputs(horse, record.id, work_dir)
    return chunk, scene, bundle_dir, CancelPoll(horse.lifecycle, record.id)


def _start_merge(horse: _Horse, job_id: str) -> float:
    """Mark the merge step running; its start on the monotonic clock (seconds)."""
    horse.lifecycle.start_merge(job_id, horse.worker_name, os.getpid())
    return time.monotonic()


def render_chunk_task(job_id: str, chunk_index: int) -> dict[str, Any]:
    """Render chunk ``chunk_index`` of job ``job_id`` and upload its partial (streamed tile by tile)."""
    horse = _Horse.current()
    record = horse.lifecycle.record(job_id)
    if record is None or record.is_final:
        return _skipped(record)
    from worker.render.chunks import render_chunk
    from worker.render.renderer import RenderCanceledError

    with horse_work_dir(f"{job_id}-{chunk_index}") as tmp:
        chunk, scene, bundle_dir, should_stop = _start_chunk(horse, record, chunk_index, Path(tmp))
        partial_path = Path(tmp) / f"chunk-{chunk_index}.npz"
        try:
            result = render_chunk(
                scene,
                chunk,
                partial_path,
                progress=horse.progress(job_id, chunk_index),
                should_stop=should_stop,
                bundle_dir=bundle_dir,
                limits=horse.settings,
            )
        except RenderCanceledError:
            result = None
        if result is None or should_stop(force=True):
            horse.lifecycle.mark_chunk_canceled(job_id, chunk_index)
            return {"canceled": True}
        horse.lifecycle.store.put_file(chunk_key(job_id, chunk_index), partial_path)
    horse.lifecycle.finish_chunk(job_id, chunk_index, result["samples"], result["seconds"])
    return {"samples": result["samples"], "seconds": result["seconds"]}


def render_job_task(job_id: str) -> dict[str, Any]:
    """Render a job of one chunk (or a noise-target job, which adds rounds in this horse) and write its
    final artifacts, streamed tile by tile, in one work horse. A failure on the last attempt fails the
    job with the step's error."""
    horse = _Horse.current()
    try:
        record = horse.lifecycle.record(job_id)
        if record is None or record.is_final:
            return _skipped(record)
        from worker.render.chunks import render_to_dir
        from worker.render.renderer import RenderCanceledError

        with horse_work_dir(job_id) as tmp:
            work_dir = Path(tmp)
            out_dir = work_dir / "out"
            with _step("chunk 0"):
                chunk, scene, bundle_dir, should_stop = _start_chunk(horse, record, 0, work_dir)
                target = record.noise_target
                previews = (
                    None
                    if target is None
                    else RoundPreviews(horse.lifecycle, job_id, target, chunk.seed, work_dir)
                )
                try:
                    summary = render_to_dir(
                        scene,
                        out_dir,
                        [chunk],
                        progress=horse.progress(job_id, 0),
                        should_stop=should_stop,
                        bundle_dir=bundle_dir,
                        limits=horse.settings,
                        target=target,
                        on_round=previews,
                        extra_summary={"job_id": job_id},
                    )
                except RenderCanceledError:
                    summary = None
            if summary is None or should_stop(force=True):
                horse.lifecycle.mark_chunk_canceled(job_id, 0)
                return {"canceled": True}
            horse.lifecycle.finish_chunk(job_id, 0, summary["samples"], summary["render_seconds"])
            with _step(MERGE_STEP):
                merge_started_s = _start_merge(horse, job_id)
                return horse.lifecycle.finalize(job_id, out_dir, summary, merge_started_s)
    except StepFailedError as error:
        _fail_on_last_attempt(horse, job_id, str(error))
        raise


def merge_task(job_id: str) -> dict[str, Any]:
    """Merge the chunks of ``job_id`` into the final artifacts, or fail the job if a chunk failed. An
    error in the merge itself is retried like a chunk's; the last attempt fails the job with it."""
    horse = _Horse.current()
    try:
        record = horse.lifecycle.record(job_id)
        if record is None or record.is_final:
            return _skipped(record)
        failures = chunk_failures(horse.lifecycle.client, job_id, record.chunk_count)
        if failures:
            horse.lifecycle.fail(job_id, "; ".join(failures))
            return {"failed": failures}
        with _step(MERGE_STEP), horse_work_dir(f"{job_id}-merge") as tmp:
            from worker.render.chunks import merge_chunks

            merge_started_s = _start_merge(horse, job_id)
            work_dir = Path(tmp)
            chunk_paths = [work_dir / "chunks" / f"{index}.npz" for index in range(record.chunk_count)]
            for index, path in enumerate(chunk_paths):
                horse.lifecycle.store.get_file(chunk_key(job_id, index), path)
            out_dir = work_dir / "out"
            summary = merge_chunks(
                _scene(horse, job_id), chunk_paths, out_dir, extra_summary={"job_id": job_id}
            )
            return horse.lifecycle.finalize(job_id, out_dir, summary, merge_started_s)
    except StepFailedError as error:
        _fail_on_last_attempt(horse, job_id, str(error))
        raise


def evaluate_run_task(run_id: str) -> dict[str, Any]:
    """Evaluate a regression run after its renders ended (``hgcore.regression.evaluation``)."""
    horse = _Horse.current()
    run = RunEvaluator.of(horse.lifecycle, horse.settings).evaluate_run(run_id)
    return {"run_id": run.id, "status": run.status}
