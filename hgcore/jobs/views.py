"""The view of a job: what ``GET /v1/jobs/{id}`` answers and what ``manifest.json`` keeps when the job ends
(so a finished job's view outlives its Redis record). ``build_view`` aggregates a record and its chunk
bookkeeping (``keys.job_key`` / ``keys.chunks_key``) into it: progress is the mean chunk fraction."""

from __future__ import annotations

import json
import time

from pydantic import BaseModel, ConfigDict, Field

from hgcore.jobs.status import MERGE_PENDING_PROGRESS, ChunkStatus, JobStatus, Priority


def _float_or_none(value: str | None) -> float | None:
    return float(value) if value not in (None, "") else None


class ChunkView(BaseModel):
    index: int
    status: ChunkStatus
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


def _noise_target_view(record: dict[str, str]) -> NoiseTargetView | None:
    """The record's requested target (``hgcore.noise_target.RECORD_FIELDS``) plus the achieved block
    (JSON in ``noise_target``) once the job wrote it."""
    requested = {
        name: _float_or_none(record.get(name))
        for name in ("target_rel_error", "time_budget_s", "target_quantile")
    }
    if all(value is None for value in requested.values()):
        return None
    achieved = json.loads(record["noise_target"]) if record.get("noise_target") else {}
    return NoiseTargetView(**(achieved | requested))


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


def build_view(record: dict[str, str], chunk_fields: dict[str, str], now: float | None = None) -> JobView:
    """Aggregate a record and its chunk fields into the API view (progress = mean chunk fraction)."""
    now = time.time() if now is None else now
    chunk_count = int(record["chunks"])
    status = JobStatus(record["status"])
    chunks = [
        ChunkView(
            index=i,
            status=chunk_fields.get(f"{i}.status", "queued"),  # type: ignore[arg-type]
            progress=float(chunk_fields.get(f"{i}.progress", "0") or 0),
            spp=int(chunk_fields[f"{i}.spp"]) if chunk_fields.get(f"{i}.spp") else None,
            worker=chunk_fields.get(f"{i}.worker") or None,
            attempts=int(chunk_fields.get(f"{i}.attempts", "0")),
            samples=int(chunk_fields[f"{i}.samples"]) if chunk_fields.get(f"{i}.samples") else None,
            seconds=_float_or_none(chunk_fields.get(f"{i}.seconds")),
        )
        for i in range(chunk_count)
    ]
    chunks_done = sum(1 for c in chunks if c.status == "done")
    progress = 1.0 if status == JobStatus.SUCCEEDED else sum(c.progress for c in chunks) / max(1, chunk_count)
    if status != JobStatus.SUCCEEDED:
        progress = min(progress, MERGE_PENDING_PROGRESS)
    created_at = float(record["created_at"])
    started_at = _float_or_none(record.get("started_at"))
    finished_at = _float_or_none(record.get("finished_at"))
    eta_s = None
    if status == JobStatus.RUNNING and started_at is not None and progress > 0:
        eta_s = max(0.0, (now - started_at) * (1.0 - progress) / progress)
    render_seconds = [c.seconds for c in chunks if c.seconds is not None]
    workers = sorted({c.worker for c in chunks if c.worker} | {chunk_fields.get("merge.worker") or ""} - {""})
    return JobView(
        id=record["id"],
        owner=record["owner"],
        name=record.get("name") or None,
        status=status,
        progress=progress,
        eta_s=eta_s,
        priority=record["priority"],  # type: ignore[arg-type]
        spp=int(record["spp"]),
        width=int(record["width"]) if record.get("width") else None,
        height=int(record["height"]) if record.get("height") else None,
        seed=int(record["seed"]),
        chunks_total=chunk_count,
        chunks_done=chunks_done,
        workers=workers,
        error=record.get("error") or None,
        timings=JobTimings(
            created_at=created_at,
            started_at=started_at,
            finished_at=finished_at,
            queue_wait_s=started_at - created_at if started_at is not None else None,
            render_s=sum(render_seconds) if render_seconds else None,
            merge_s=_float_or_none(chunk_fields.get("merge.seconds")),
            total_s=finished_at - created_at if finished_at is not None else None,
        ),
        noise_target=_noise_target_view(record),
        chunks=chunks,
    )
