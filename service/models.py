"""Request and response bodies of the HTTP API (pydantic v2); their examples feed the OpenAPI document."""

from __future__ import annotations

from enum import StrEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field


class JobStatus(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELED = "canceled"


TERMINAL_STATUSES: frozenset[JobStatus] = frozenset(
    {JobStatus.SUCCEEDED, JobStatus.FAILED, JobStatus.CANCELED}
)

Priority = Literal["high", "normal", "low"]


class JobOptions(BaseModel):
    """Everything of a job request except the scene (shared by the JSON and multipart forms).

    Strict like the scene: ``"spp": "100"`` is an error in a JSON body. Multipart form fields are text by
    nature, so the form route validates them with ``strict=False``."""

    model_config = ConfigDict(extra="forbid", strict=True)

    priority: Priority = Field("normal", description="Queue: `high`, `normal` or `low`.")
    spp: int | None = Field(None, ge=1, description="Samples per pixel; default: the scene's own.")
    chunks: int | None = Field(None, ge=1, description="Parallel chunks (spp partitions); default: server's.")
    seed: int | None = Field(None, ge=0, le=2**32 - 1, description="Base seed; default: the scene's.")
    idempotency_key: str | None = Field(
        None,
        min_length=1,
        max_length=128,
        pattern=r"^[A-Za-z0-9._:-]+$",
        description="Repeating a request with the same key returns the first job instead of a new one.",
    )
    name: str | None = Field(None, max_length=200, description="Free-form label shown in listings.")


EXAMPLE_SCENE: dict[str, Any] = {
    "schema": "hgrender/scene/v1",
    "name": "lit floor",
    "camera": {
        "type": "perspective",
        "origin_m": [0, 1, 3],
        "target_m": [0, 0, 0],
        "up": [0, 1, 0],
        "fov_deg": 40,
    },
    "film": {"width": 32, "height": 32, "bands": 8, "spp": 16},
    "materials": {"white": {"type": "diffuse", "reflectance": 0.75}},
    "shapes": [
        {
            "type": "rectangle",
            "material": "white",
            "center_m": [0, 0, 0],
            "normal": [0, 1, 0],
            "up": [0, 0, -1],
            "width_m": 2,
            "height_m": 2,
        }
    ],
    "emitters": [
        {
            "type": "rectangle",
            "center_m": [0, 1.5, 0],
            "normal": [0, -1, 0],
            "up": [0, 0, -1],
            "width_m": 0.5,
            "height_m": 0.5,
            "spectrum": {"type": "d65"},
            "power_w": 40.0,
        }
    ],
}
"""A small valid scene (a lit floor) for the OpenAPI examples."""


class JobCreate(JobOptions):
    """``POST /v1/jobs`` JSON body."""

    scene: dict[str, Any] = Field(description="Scene document, schema `hgrender/scene/v1`.")

    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [
                {
                    "scene": EXAMPLE_SCENE,
                    "priority": "normal",
                    "spp": 64,
                    "chunks": 4,
                    "idempotency_key": "nightly-2026-11-21-cornell",
                }
            ]
        },
    )


class JobCreated(BaseModel):
    id: str = Field(examples=["3f2a9c0d4b1e4f6a8d7c6b5a4e3d2c1b"])
    status: JobStatus = Field(examples=["queued"])


class ChunkView(BaseModel):
    index: int
    status: Literal["queued", "running", "done", "failed", "canceled"]
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
    seed: int
    chunks_total: int
    chunks_done: int
    workers: list[str] = Field(default_factory=list, description="Workers that ran chunks or the merge.")
    error: str | None = None
    timings: JobTimings
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


class JobList(BaseModel):
    items: list[JobView]
    total: int = Field(description="Jobs matching the filter.")
    offset: int
    limit: int


class ArtifactView(BaseModel):
    name: str = Field(examples=["image.exr"])
    size_bytes: int
    url: str = Field(description="Download path.", examples=["/v1/jobs/3f2a.../artifacts/image.exr"])


class ArtifactList(BaseModel):
    job_id: str
    items: list[ArtifactView]


class TokenCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    owner: str = Field(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9._@-]+$", examples=["alice"])
    scopes: list[Literal["submit", "read", "admin"]] = Field(min_length=1, examples=[["submit", "read"]])
    name: str = Field("", max_length=200)


class TokenView(BaseModel):
    id: str
    owner: str
    scopes: list[str]
    name: str
    created_at: float


class TokenCreated(TokenView):
    token: str = Field(description="The secret; shown only once.")


class Problem(BaseModel):
    """Error body: ``detail`` says what is wrong; ``errors`` lists scene validation problems."""

    detail: str
    errors: list[dict[str, Any]] | None = None
