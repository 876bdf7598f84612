"""The settings of every hgrender server-side process, read once from ``HGRENDER_*`` environment variables.

One story per process (``docs/configuration.md``): the API, each queue worker and its work horses, the
scheduler and a local ``hgrender render`` build one ``Settings()`` at start and pass it down; ``hgrender
serve`` hands its own to the workers it starts (``Settings.to_env``). ``SceneLimits`` is the part that
scene validation needs (``schemas`` takes it as an argument); ``Settings`` extends it, so a process's
settings *are* its limits. The command-line client reads only ``HGRENDER_URL`` and ``HGRENDER_TOKEN``
(``hgrender.cli.connection``). ``REDIS_URL`` is read without the prefix (the usual name in container
deployments); when it is unset, ``hgrender serve`` starts a private Redis.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Literal

from pydantic import AliasChoices, Field, ValidationInfo, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from hgcore.errors import InputError

QUEUE_NAMES: tuple[str, ...] = ("high", "default", "low")
"""RQ queues in dequeue order; a job's ``priority`` picks one."""


class SceneLimits(BaseSettings):
    """Resource limits on accepted scenes (enforced by :func:`schemas.validation.validate_scene` and the
    USD/mesh importers): every limit guards the API and workers against scenes too expensive to parse or
    render. The collection limits (materials, shapes, emitters, mesh sizes, spectrum tables, strings) are
    checked on the raw document before the schema validates it, so an oversized scene costs one walk over
    its JSON, never a full validation or a render.

    Environment variable for each field: ``HGRENDER_`` + the field name in upper case
    (e.g. ``HGRENDER_MAX_SPP=4096``).
    """

    model_config = SettingsConfigDict(env_prefix="HGRENDER_", extra="ignore", frozen=True)

    max_resolution: int = Field(4096, ge=1, description="Largest film width or height, pixels.")
    max_pixels: int = Field(4096 * 4096, ge=1, description="Largest film width × height, pixels.")
    max_spp: int = Field(65536, ge=1, description="Largest samples per pixel.")
    max_bands: int = Field(64, ge=1, le=64, description="Largest number of spectral bands.")
    max_primitives: int = Field(
        10000, ge=1, description="Largest number of shapes + emitters (and of geometry prims in a USD stage)."
    )
    max_triangles: int = Field(
        2_000_000, ge=1, description="Largest total triangle count over all meshes (inline, files, USD)."
    )
    max_vertices: int = Field(2_000_000, ge=1, description="Largest total vertex count over all meshes.")
    max_materials: int = Field(1000, ge=1, description="Largest number of materials in a scene.")
    max_emitters: int = Field(1000, ge=1, description="Largest number of emitters in a scene.")
    max_spectrum_samples: int = Field(
        4096, ge=2, le=10000, description="Largest number of samples of one tabulated spectrum."
    )
    max_string_chars: int = Field(
        1024, ge=64, description="Longest string (value or object key) anywhere in a scene document."
    )
    max_file_bytes: int = Field(
        64 * 1024 * 1024, ge=1, description="Largest single uploaded file (JSON, USD layer, mesh), bytes."
    )
    max_bundle_bytes: int = Field(
        256 * 1024 * 1024, ge=1, description="Largest total unpacked size of an uploaded bundle, bytes."
    )
    max_bundle_files: int = Field(1000, ge=1, description="Largest number of files in an uploaded bundle.")
    max_textures: int = Field(
        64, ge=0, description="Largest number of image files a scene's textures and environment read."
    )
    max_texture_pixels: int = Field(
        8192 * 4096, ge=1, description="Largest width × height of one texture or environment image, pixels."
    )
    max_texture_bytes: int = Field(
        1024 * 1024 * 1024,
        ge=1,
        description="Largest decoded size of all a scene's images together (width × height × channels × 4 "
        "bytes: float32), bytes.",
    )
    max_usd_prims: int = Field(100_000, ge=1, description="Largest number of prims traversed in a USD stage.")
    max_usd_memory_bytes: int = Field(
        2 * 1024 * 1024 * 1024,
        ge=64 * 1024 * 1024,
        description="Address-space rlimit of the USD parser process.",
    )
    usd_timeout_s: float = Field(
        60.0, gt=0.0, description="Wall-clock limit of the USD parser process, seconds."
    )


class Settings(SceneLimits):
    """All knobs of the API, the queue workers, the renderer and the artifact store, and the scene limits."""

    model_config = SettingsConfigDict(
        env_prefix="HGRENDER_", extra="ignore", validate_default=True, frozen=True
    )

    data_dir: Path = Field(
        Path("./data"), description="Root for the embedded Redis, artifacts and admin token."
    )
    redis_url: str | None = Field(
        None,
        validation_alias=AliasChoices("REDIS_URL", "HGRENDER_REDIS_URL"),
        description="Redis to use; unset means `hgrender serve` starts a private redis-server.",
    )
    auth: Literal["on", "off"] = Field("on", description="`off` disables bearer tokens (local development).")
    store: Literal["filesystem", "s3"] = Field("filesystem", description="Artifact store backend.")
    store_dir: Path | None = Field(None, description="Filesystem store root; default `<data_dir>/artifacts`.")
    s3_bucket: str | None = Field(None, description="S3 bucket for the `s3` store.")
    s3_prefix: str = Field("", description="Key prefix inside the S3 bucket.")
    s3_endpoint_url: str | None = Field(None, description="S3-compatible endpoint (MinIO, moto, ...).")
    s3_region: str = Field("us-east-1", description="S3 region name.")
    max_request_bytes: int = Field(64 * 1024 * 1024, gt=0, description="Largest accepted request body.")
    default_chunks: int = Field(2, ge=1, description="Chunks per job when the request names none.")
    max_chunks: int = Field(64, ge=1, description="Largest accepted `chunks` in a request.")
    job_timeout_s: int = Field(3600, gt=0, description="Wall-clock limit of one chunk or merge step.")
    chunk_retry_max: int = Field(3, ge=0, description="Retries of a chunk whose worker failed or died.")
    chunk_retry_intervals_s: list[int] = Field(
        default_factory=lambda: [2, 10, 30], description="Backoff before retries 1, 2, 3 (s)."
    )
    result_ttl_s: int = Field(7 * 24 * 3600, gt=0, description="How long RQ keeps finished chunk results.")
    workers: int | None = Field(
        None, ge=0, description="Queue workers started by `hgrender serve`; default max(1, cores // 2)."
    )
    render_threads: int | None = Field(
        None,
        ge=1,
        description="Dr.Jit CPU threads per rendering process; `hgrender serve` default: cores // workers "
        "(workers share the cores instead of oversubscribing them), elsewhere all cores.",
    )
    variant: Literal["auto", "llvm_ad_spectral", "cuda_ad_spectral"] = Field(
        "auto",
        description="Mitsuba variant of the renderer: `auto` is CUDA where a GPU is usable, else LLVM.",
    )
    worker_monitoring_interval_s: int = Field(
        5, ge=1, description="How often a worker heartbeats while its work horse renders."
    )
    worker_heartbeat_grace_s: int = Field(
        10,
        ge=1,
        description="Seconds past a missed heartbeat after which a running chunk counts as abandoned "
        "(its worker died); the heartbeat comes from the worker process, not the render, so a long chunk "
        "keeps beating.",
    )
    worker_maintenance_interval_s: int = Field(
        5, ge=1, description="How often idle workers look for abandoned chunks of dead workers."
    )
    reconcile_interval_s: int = Field(
        30,
        ge=1,
        description="How often one worker checks that every unfinished job's chunks are queued, running or "
        "scheduled somewhere, and re-enqueues those that are not (a crash between two steps can strand one).",
    )
    worker_redis_outage_s: float = Field(
        30.0,
        gt=0,
        description="Workers retry each Redis command this long (back-off ≤ 1 s) before they give up the "
        "chunk, wait for Redis and start over.",
    )
    worker_ttl_s: int = Field(
        420, ge=5, description="Lifetime of an idle worker's registration between beats."
    )
    worker_shutdown_grace_s: int = Field(
        40,
        ge=1,
        description="On SIGTERM a worker takes no new chunk and lets its current one finish within this "
        "(s); then it stops the chunk and hands it back to the queue.",
    )
    rate_limit_per_minute: int = Field(6000, ge=1, description="Requests per token per minute (429 above).")
    idempotency_ttl_s: int = Field(
        24 * 3600, gt=0, description="How long an `idempotency_key` is remembered."
    )
    progress_interval_s: float = Field(0.25, gt=0, description="Least interval between progress events.")
    regression_scheduler: bool = Field(
        True, description="`hgrender serve` runs the regression scheduler (leader-elected, so one fires)."
    )
    regression_misfire_grace_s: int = Field(
        3600, ge=1, description="Due regression runs later than this (scheduler down) are skipped, not run."
    )
    regression_leader_ttl_s: float = Field(
        10.0, gt=0, description="Leader lease (s): a standby scheduler takes over within this after a crash."
    )
    regression_webhook_retry_intervals_s: list[float] = Field(
        default_factory=lambda: [2.0, 10.0, 60.0], description="Backoff before failure-webhook retries (s)."
    )
    regression_webhook_timeout_s: float = Field(10.0, gt=0, description="Timeout of one webhook POST (s).")

    @field_validator("chunk_retry_intervals_s", "regression_webhook_retry_intervals_s")
    @classmethod
    def _intervals_non_negative(cls, value: list[float], info: ValidationInfo) -> list[float]:
        if any(v < 0 for v in value):
            raise InputError(f"{info.field_name}: intervals must be >= 0 seconds")
        return value

    @model_validator(mode="after")
    def _s3_needs_bucket(self) -> Settings:
        if self.store == "s3" and not self.s3_bucket:
            raise InputError("s3_bucket: required when store is 's3'")
        return self

    def to_env(self) -> dict[str, str]:
        """These settings as environment variables (for child processes such as workers)."""
        env = {}
        for name, value in self.model_dump(mode="json").items():
            if value is None:
                continue
            key = "REDIS_URL" if name == "redis_url" else f"HGRENDER_{name.upper()}"
            env[key] = json.dumps(value) if isinstance(value, list) else str(value)
        return env

    @property
    def artifact_dir(self) -> Path:
        """Filesystem store root."""
        return self.store_dir if self.store_dir is not None else self.data_dir / "artifacts"

    @property
    def auth_enabled(self) -> bool:
        return self.auth == "on"

    @property
    def render_threads_per_worker(self) -> int:
        """Dr.Jit threads for each of ``worker_count`` workers started by ``hgrender serve``."""
        if self.render_threads is not None:
            return self.render_threads
        return max(1, (os.cpu_count() or 1) // max(1, self.worker_count))

    @property
    def worker_count(self) -> int:
        """Workers for ``hgrender serve``: one per two cores, because a render's LLVM kernels are
        multi-threaded and already use more than one core each."""
        if self.workers is not None:
            return self.workers
        return max(1, (os.cpu_count() or 1) // 2)
