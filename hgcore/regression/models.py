"""Request and response bodies of regression suites, schedules, runs and baselines (pydantic v2).

A *suite* lists scenes (an example of ``schemas/examples``, the stored scene of an earlier job, or an inline
scene document) with film overrides and pass/fail thresholds; a *schedule* runs a suite on a 5-field cron
expression (in a time zone) or every ``interval_s`` seconds; each run renders every scene and compares it
with the scene's current baseline (``hgcore.regression.metrics``).
"""

from __future__ import annotations

import zoneinfo
from typing import Any, Literal

from croniter import croniter
from pydantic import BaseModel, ConfigDict, Field, HttpUrl, field_validator, model_validator

from hgcore.errors import InputError

SCENE_NAME_PATTERN = r"^[A-Za-z0-9._-]{1,100}$"


class Thresholds(BaseModel):
    """Pass/fail limits of one scene; a metric fails only when it exceeds its limit AND the difference is
    statistically significant (|z| > ``z_critical``), so Monte Carlo noise alone never fails a scene."""

    model_config = ConfigDict(extra="forbid")

    z_critical: float = Field(
        5.0, gt=0, description="Significance: |z| above this is not explained by Monte Carlo noise."
    )
    max_rel_mean_change: float = Field(
        0.05, ge=0, description="Largest |relative change| of any spectral band's image mean."
    )
    max_rel_rmse: float = Field(
        0.05, ge=0, description="Largest noise-corrected relative RMSE of any spectral band."
    )
    max_delta_e00_p95: float = Field(
        2.0, ge=0, description="Largest 95th percentile of per-pixel ΔE₀₀ above its noise level."
    )
    max_flip_mean: float = Field(
        0.05, ge=0, description="Largest mean per-pixel ꟻLIP error (0..1) above its noise level."
    )
    max_coherence_drift: float = Field(
        0.05, ge=0, description="Largest |median relative change| of ℓ₁, ℓ₂ or anisotropy."
    )


class SuiteScene(BaseModel):
    """One scene of a suite: exactly one of ``example``, ``job_id`` or ``scene``."""

    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(
        None, pattern=SCENE_NAME_PATTERN, description="Baseline key; default: the example's name."
    )
    example: str | None = Field(
        None, pattern=SCENE_NAME_PATTERN, description="A file of `schemas/examples` (without `.json`)."
    )
    job_id: str | None = Field(None, pattern=r"^[0-9a-f]{32}$", description="Reuse this job's stored scene.")
    scene: dict[str, Any] | None = Field(None, description="Inline scene document (`hgrender/scene/v1`).")
    spp: int | None = Field(None, ge=1, description="Override of `film.spp`.")
    width: int | None = Field(None, ge=1, description="Override of `film.width` (px).")
    height: int | None = Field(None, ge=1, description="Override of `film.height` (px).")
    thresholds: Thresholds | None = Field(None, description="Per-scene thresholds (else the suite's).")

    @model_validator(mode="after")
    def _one_source(self) -> SuiteScene:
        sources = [s for s in (self.example, self.job_id, self.scene) if s is not None]
        if len(sources) != 1:
            raise InputError("example: give exactly one of example, job_id or scene")
        if self.name is None:
            if self.example is None:
                raise InputError("name: required unless the scene is an example")
            self.name = self.example
        return self

    @property
    def key(self) -> str:
        """The scene's baseline key (its name)."""
        assert self.name is not None
        return self.name


class Suite(BaseModel):
    """Scenes to render and their default thresholds."""

    model_config = ConfigDict(extra="forbid")

    scenes: list[SuiteScene] = Field(min_length=1, max_length=100)
    thresholds: Thresholds = Field(default_factory=Thresholds)

    @field_validator("scenes")
    @classmethod
    def _unique_names(cls, scenes: list[SuiteScene]) -> list[SuiteScene]:
        names = [scene.key for scene in scenes]
        duplicates = sorted({name for name in names if names.count(name) > 1})
        if duplicates:
            raise InputError(f"scenes: duplicate scene names {duplicates}")
        return scenes

    def thresholds_for(self, scene: SuiteScene) -> Thresholds:
        return scene.thresholds if scene.thresholds is not None else self.thresholds


class ScheduleCreate(BaseModel):
    """``POST /v1/schedules``."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {
                    "name": "nightly",
                    "cron": "0 2 * * *",
                    "timezone": "Europe/Berlin",
                    "suite": {
                        "scenes": [{"example": "cornell_box", "spp": 64, "width": 64, "height": 64}],
                        "thresholds": {"max_delta_e00_p95": 2.0},
                    },
                    "webhook_url": "https://ci.example.org/hooks/hgrender",
                }
            ]
        },
    )

    name: str = Field(min_length=1, max_length=200)
    cron: str | None = Field(None, description="5-field cron expression, evaluated in `timezone`.")
    interval_s: int | None = Field(
        None, ge=1, le=366 * 24 * 3600, description="Run every this many seconds (instead of cron), ≤ 1 year."
    )
    timezone: str = Field("UTC", description="IANA time zone of the cron expression.")
    suite: Suite
    webhook_url: HttpUrl | None = Field(None, description="POSTed a JSON report when a run fails.")
    paused: bool = False

    @field_validator("cron")
    @classmethod
    def _valid_cron(cls, value: str | None) -> str | None:
        if value is not None and (len(value.split()) != 5 or not croniter.is_valid(value)):
            raise InputError(f"cron: {value!r} is not a valid 5-field cron expression")
        return value

    @field_validator("timezone")
    @classmethod
    def _valid_timezone(cls, value: str) -> str:
        try:
            zoneinfo.ZoneInfo(value)
        except (zoneinfo.ZoneInfoNotFoundError, ValueError):
            raise InputError(f"timezone: {value!r} is not an IANA time zone") from None
        return value

    @model_validator(mode="after")
    def _cron_or_interval(self) -> ScheduleCreate:
        if (self.cron is None) == (self.interval_s is None):
            raise InputError("cron: give exactly one of cron or interval_s")
        return self


class ScheduleView(ScheduleCreate):
    """A stored schedule."""

    id: str
    owner: str
    created_at: float = Field(description="Unix time (s); interval schedules count from here.")
    next_run_at: float | None = Field(None, description="Next due time known to the scheduler (Unix s).")


class ScheduleList(BaseModel):
    items: list[ScheduleView]


Verdict = Literal["pass", "fail", "error"]


class SceneResult(BaseModel):
    """One scene of a run: its render job, the baseline it was compared with, metrics and verdict."""

    scene: str
    job_id: str | None = None
    baseline_version: int | None = None
    baseline_job_id: str | None = None
    verdict: Verdict | None = Field(None, description="None while rendering.")
    reasons: list[str] = Field(default_factory=list, description="Why it failed, naming scene and metric.")
    metrics: dict[str, Any] = Field(default_factory=dict)


class RunView(BaseModel):
    """One run of a suite (scheduled, run-now or promoted)."""

    id: str
    owner: str = Field(
        description="Owner of the render jobs (the schedule's, or the caller of POST /v1/runs)."
    )
    schedule_id: str | None = None
    trigger: Literal["schedule", "manual", "cli"]
    due_at: float | None = Field(None, description="The schedule's due time this run fulfils (Unix s).")
    created_at: float
    finished_at: float | None = None
    status: Literal["running", "passed", "failed", "error"]
    reasons: list[str] = Field(default_factory=list)
    scenes: list[SceneResult]
    suite: Suite | None = Field(None, description="The suite as it was when the run started.")
    webhook_url: str | None = None
    webhook: dict[str, Any] | None = Field(None, description="Delivery outcome of the failure webhook.")


class RunCreate(BaseModel):
    """``POST /v1/runs``: run a suite once, outside any schedule (``hgrender regress --url``)."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {
                    "suite": {"scenes": [{"example": "cornell_box", "spp": 16, "width": 32, "height": 32}]},
                    "webhook_url": "https://ci.example.com/hooks/hgrender",
                }
            ]
        },
    )

    suite: Suite
    webhook_url: HttpUrl | None = Field(None, description="POSTed a JSON report when the run fails.")


class RunList(BaseModel):
    items: list[RunView]
    series: dict[str, list[dict[str, Any]]] = Field(
        description="Per scene, oldest first: run id, time, verdict, the quantities the verdict tests "
        "(ΔE₀₀ p95 excess, ꟻLIP mean excess, worst band rel. RMSE) and the raw ΔE₀₀ p95, ꟻLIP mean."
    )


class BaselineView(BaseModel):
    scene: str
    version: int
    job_id: str
    run_id: str | None = None
    created_at: float
    files: list[str]


class BaselineList(BaseModel):
    scene: str
    current: int | None
    versions: list[BaselineView]


class PromoteRequest(BaseModel):
    """``POST /v1/baselines``: a job (with ``scene``) or a whole run becomes the baseline."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {"run_id": "9c1d2e3f4a5b6c7d8e9f0a1b2c3d4e5f"},
                {"job_id": "3f2a9c0d4b1e4f6a8d7c6b5a4e3d2c1b", "scene": "cornell_box"},
            ]
        },
    )

    job_id: str | None = Field(None, pattern=r"^[0-9a-f]{32}$")
    scene: str | None = Field(None, pattern=SCENE_NAME_PATTERN, description="Scene key, with `job_id`.")
    run_id: str | None = Field(None, pattern=r"^[0-9a-f]{32}$")

    @model_validator(mode="after")
    def _job_or_run(self) -> PromoteRequest:
        if (self.job_id is None) == (self.run_id is None):
            raise InputError("job_id: give exactly one of job_id (with scene) or run_id")
        if self.job_id is not None and self.scene is None:
            raise InputError("scene: required with job_id")
        return self
