"""Resource limits on accepted scenes, configurable per deployment through ``HGRENDER_MAX_*`` variables.

Every limit guards the API and workers against scenes that are too expensive to parse or render. The
collection limits (materials, shapes, emitters, mesh sizes, spectrum tables, strings) are checked on the
raw document before the schema validates it, so an oversized scene costs one walk over its JSON, never a
full validation or a render.
"""

from __future__ import annotations

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class SceneLimits(BaseSettings):
    """Limits enforced by :func:`schemas.validation.validate_scene` and the USD/mesh importers.

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
    max_usd_prims: int = Field(100_000, ge=1, description="Largest number of prims traversed in a USD stage.")
    max_usd_memory_bytes: int = Field(
        2 * 1024 * 1024 * 1024,
        ge=64 * 1024 * 1024,
        description="Address-space rlimit of the USD parser process.",
    )
    usd_timeout_s: float = Field(
        60.0, gt=0.0, description="Wall-clock limit of the USD parser process, seconds."
    )
