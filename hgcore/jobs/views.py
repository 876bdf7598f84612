"""The view of a job: what ``GET /v1/jobs/{id}`` answers and what ``manifest.json`` keeps when the job ends
(so a finished job's view outlives its Redis record). ``build_view`` aggregates a job record and its steps
(``record.JobRecord``, ``record.JobSteps``) into it: progress is the mean chunk fraction."""

from __future__ import annotations

import time

from pydantic import BaseModel, ConfigDict, Field

from hgcore.jobs.record import JobRecord, JobSteps
from hgcore.jobs.status import MERGE_PENDING_PROGRESS, JobStatus, Priority, StepStatus


class ChunkView(BaseModel):
    index: int
    status: StepStatus
    progress: float = Field(ge=0.0, le=1.0)
    spp: int | None = None
    worker: str | None = None
    attempts: int = 0
    samples: int | None = None
    seconds: float | None = None


class JobTimings(BaseModel):
    created_at: float = Field(description="Unix time (s).")
    started_at: float | None = Field(None, description="First chunk started (Unix time, s).")
    finished_at: float | None = Field(None, description="Reached a final status (Unix time, s).")
    queue_wait_s: float | None = None
    render_s: float | None = Field(None, description="Sum of chunk render times (s).")
    merge_s: float | None = None
    total_s: float | None = None


class NoiseTargetView(BaseModel):
    """A noise-target job's request and, once it succeeded, what it achieved (``summary.json``'s
    ``noise_target`` block, ``hgcore.noise_target``)."""

    target_rel_error: float | None = Field(None, description="Requested relative standard error.")
    time_budget_s: float | None = Field(None, description="Requested render time budget (s).")
    target_quantile: float | None = Field(None, description="Pixel quantile of the luminance measure.")
    metric: str | None = Field(None, description="`band_mean` or `luminance_quantile`.")
    achieved_rel_error: float | None = Field(None, description="The error reached, in `metric`.")
    band_rel_error: list[float] | None = Field(None, description="Relative error of each band's mean.")
    met: bool | None = Field(None, description="Whether `achieved_rel_error` ≤ `target_rel_error`.")
    stop_reason: str | None = Field(None, description="`target_met`, `time_budget` or `max_spp`.")
    spp: int | None = Field(None, description="Samples per pixel rendered in all rounds.")
    rounds: list[dict[str, float]] | None = Field(None, description="Each round's total spp, s, error.")


def _noise_target_view(record: JobRecord) -> NoiseTargetView | None:
    """The record's requested target plus, once the job wrote it, the block of its rounds."""
    requested = {
        "target_rel_error": record.target_rel_error,
        "time_budget_s": record.time_budget_s,
        "target_quantile": record.target_quantile,
    }
    if all(value is None for value in requested.values()):
        return None
    return NoiseTargetView(**((record.noise_target_outcome or {}) | requested))


class JobView(BaseModel):
    """``GET /v1/jobs/{id}``."""

    id: str
    owner: str
    name: str | None = None
    status: JobStatus
    progress: float = Field(ge=0.0, le=1.0, description="Fraction done, aggregated over chunks.")
    eta_s: float | None = Field(None, description="Estimated seconds to completion while running.")
    priority: Priority
    spp: int
    width: int | None = Field(None, description="Image width (px) of the scene's film.")
    height: int | None = Field(None, description="Image height (px) of the scene's film.")
    seed: int
    chunks_total: int
    chunks_done: int
    workers: list[str] = Field(default_factory=list, description="Workers that ran chunks or the merge.")
    error: str | None = None
    timings: JobTimings
    noise_target: NoiseTargetView | None = Field(
        None, description="A noise-target job's request and achieved error (null: a fixed-spp job)."
    )
    chunks: list[ChunkView] = Field(default_factory=list)

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "id": "3f2a9c0d4b1e4f6a8d7c6b5a4e3d2c1b",
                    "owner": "alice",
                    "status": "running",
                    "progress": 0.42,
                    "eta_s": 12.5,
                    "priority": "normal",
                    "spp": 64,
                    "seed": 1234,
                    "chunks_total": 4,
                    "chunks_done": 1,
                    "workers": ["worker-a"],
                    "timings": {"created_at": 1795300000.0, "started_at": 1795300000.2},
                }
            ]
        }
    )


def build_view(record: JobRecord, steps: JobSteps, now: float | None = None) -> JobView:
    """Aggregate a record and its steps into the API view (progress = mean chunk fraction)."""
    now = time.time() if now is None else now
    chunks = [
        ChunkView(
            index=i,
            status=step.status,
            progress=step.progress,
            spp=step.spp,
            worker=step.worker,
            attempts=step.attempts,
            samples=step.samples,
            seconds=step.seconds,
        )
        for i, step in enumerate(steps.chunks)
    ]
    chunk_count = record.chunk_count
    chunks_done = sum(1 for c in chunks if c.status == "done")
    status = record.status
    progress = 1.0 if status == JobStatus.SUCCEEDED else sum(c.progress for c in chunks) / max(1, chunk_count)
    if status != JobStatus.SUCCEEDED:
        progress = min(progress, MERGE_PENDING_PROGRESS)
    created_at, started_at, finished_at = record.created_at, record.started_at, record.finished_at
    eta_s = None
    if status == JobStatus.RUNNING and started_at is not None and progress > 0:
        eta_s = max(0.0, (now - started_at) * (1.0 - progress) / progress)
    render_seconds = [c.seconds for c in chunks if c.seconds is not None]
    merge_worker = steps.merge.worker if steps.merge is not None else None
    workers = sorted({c.worker for c in chunks if c.worker} | ({merge_worker} if merge_worker else set()))
    return JobView(
        id=record.id,
        owner=record.owner,
        name=record.name,
        status=status,
        progress=progress,
        eta_s=eta_s,
        priority=record.priority,
        spp=record.spp,
        width=record.width,
        height=record.height,
        seed=record.seed,
        chunks_total=chunk_count,
        chunks_done=chunks_done,
        workers=workers,
        error=record.error,
        timings=JobTimings(
            created_at=created_at,
            started_at=started_at,
            finished_at=finished_at,
            queue_wait_s=started_at - created_at if started_at is not None else None,
            render_s=sum(render_seconds) if render_seconds else None,
            merge_s=steps.merge.seconds if steps.merge is not None else None,
            total_s=finished_at - created_at if finished_at is not None else None,
        ),
        noise_target=_noise_target_view(record),
        chunks=chunks,
    )
