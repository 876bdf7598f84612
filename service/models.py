"""Request and response bodies of the HTTP API (pydantic v2); their examples feed the OpenAPI document.

The job's own view (``JobView``) and statuses are the job domain's (``hgcore.jobs``), the regression
bodies the regression domain's (``hgcore.regression.models``); this module holds what only the API speaks:
request bodies, lists, artifacts, tokens, error bodies and the viewer's data.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from hgcore.jobs.status import JobStatus, Priority
from hgcore.jobs.views import JobView
from schemas import build
from schemas.gallery import GalleryView


class JobOptions(BaseModel):
    """Everything of a job request except the scene (shared by the JSON and multipart forms).

    Strict like the scene: ``"spp": "100"`` is an error in a JSON body. Multipart form fields are text by
    nature, so the form route validates them with ``strict=False``."""

    model_config = ConfigDict(extra="forbid", strict=True)

    priority: Priority = Field("normal", description="Queue: `high`, `normal` or `low`.")
    spp: int | None = Field(None, ge=1, description="Samples per pixel; default: the scene's own.")
    chunks: int | None = Field(None, ge=1, description="Parallel chunks (spp partitions); default: server's.")
    seed: int | None = Field(None, ge=0, le=2**32 - 1, description="Base seed; default: the scene's.")
    integrator: Literal["hg_path", "rlt"] | None = Field(
        None,
        description="`hg_path` (partially coherent transport) or `rlt` (the radiometric baseline: a "
        "coherent plane wave per sample); default: the scene's `film.integrator`.",
    )
    target_rel_error: float | None = Field(
        None,
        gt=0,
        lt=1,
        description="Noise target: add passes until the relative standard error of every band's image "
        "mean (or, with `target_quantile`, of the pixel luminance at that quantile) is at most this; "
        "`spp` is then the first pass's. The job renders as one chunk.",
    )
    time_budget_s: float | None = Field(
        None, gt=0, description="Noise target: add passes while the render time stays within this (s)."
    )
    target_quantile: float | None = Field(
        None,
        gt=0,
        le=1,
        description="Measure `target_rel_error` per pixel (luminance) at this quantile of the lit pixels.",
    )
    idempotency_key: str | None = Field(
        None,
        min_length=1,
        max_length=128,
        pattern=r"^[A-Za-z0-9._:-]+$",
        description="Repeating a request with the same key returns the first job instead of a new one.",
    )
    name: str | None = Field(None, max_length=200, description="Free-form label shown in listings.")


EXAMPLE_SCENE: dict[str, Any] = build.scene(
    "lit floor",
    camera=build.camera([0, 1, 3], [0, 0, 0], up=[0, 1, 0], fov_deg=40),
    film=build.film(32, bands=8, spp=16),
    materials={"white": {"type": "diffuse", "reflectance": 0.75}},
    shapes=[build.rectangle([0, 0, 0], normal=[0, 1, 0], up=[0, 0, -1], width_m=2, material="white")],
    emitters=[
        build.rectangle(
            [0, 1.5, 0], normal=[0, -1, 0], up=[0, 0, -1], width_m=0.5, spectrum={"type": "d65"}, power_w=40.0
        )
    ],
)
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
    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"owner": "alice", "scopes": ["submit", "read"], "name": "laptop"}]},
    )

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


# ---- the viewer's data (``service.api.routes.viewer``) ------------------------------------------------


class LayerView(BaseModel):
    name: str = Field(examples=["S0.555,000000nm"])
    kind: str = Field(description="rgb, band, coherence or geometry.")
    unit: str = Field(examples=["W·m⁻²·sr⁻¹·nm⁻¹"])
    wavelength_nm: float | None = None
    channels: int = Field(description="3 for `rgb` (interleaved R, G, B), else 1.")
    min: float | None = None
    max: float | None = None
    p01: float | None = Field(None, description="1st percentile (diagnostics: over covered pixels).")
    p99: float | None = Field(None, description="99th percentile.")


class LayerCatalogue(BaseModel):
    job_id: str
    width: int
    height: int
    wavelengths_nm: list[float]
    layers: list[LayerView]
    partial: bool = Field(
        False,
        description="True while the job runs: merged from its finished chunks (a noise-target job: the "
        "rounds finished so far, replaced after each round).",
    )
    spp: int | None = Field(
        None, description="Samples per pixel of a partial image (a running job's preview); null otherwise."
    )
    uploaded: bool = Field(False, description="True for an EXR dropped into the viewer (POST /v1/images).")
    exposure_ev: float = Field(
        description="Automatic exposure (EV): maps the 99th percentile of luminance Y (from the bands) to "
        "white; the viewer and compare view open at it, and regression runs use it for ΔE₀₀ and ꟻLIP."
    )


class UploadedImage(BaseModel):
    id: str = Field(description="Use it in place of a job id with every viewer endpoint (`#/view/<id>`).")
    width: int
    height: int
    wavelengths_nm: list[float]


class PixelView(BaseModel):
    x: int
    y: int
    wavelengths_nm: list[float]
    spectrum: list[float | None]
    spectrum_unit: str
    rgb: list[float | None] = Field(description="Linear sRGB.")
    coherence_covered: bool = Field(description="Whether the pixel carries coherence diagnostics.")
    coherence: dict[str, float | None] = Field(
        description="l1_um, l2_um (µm), angle (rad, image +y up), anisotropy, area_um2 (µm²), r_m (m), "
        "Mxx, Mxy, Myy (m⁻²)."
    )
    coherence_weight: float | None
    depth_m: float | None
    normal: list[float | None]
    albedo: list[float | None]


class Ellipse(BaseModel):
    x: int = Field(description="Pixel column (from the left).")
    y: int = Field(description="Pixel row (from the top).")
    l1_um: float
    l2_um: float
    angle: float = Field(description="Orientation of the ℓ₁ axis (rad, from +x towards image +y up).")
    area_um2: float


class EllipseGrid(BaseModel):
    job_id: str
    width: int
    height: int
    spacing: int
    ellipses: list[Ellipse]


class ExampleScene(BaseModel):
    name: str = Field(examples=["cornell_box.json"])
    title: str = Field(examples=["Cornell box"])
    figure: str | None = Field(
        default=None, description="The paper figure a gallery scene reproduces.", examples=["Fig. 7 (right)"]
    )
    view: GalleryView | None = Field(
        default=None, description="The most telling view of a finished render of a gallery scene."
    )
    thumbnail: str | None = Field(
        default=None,
        description="Path of a gallery scene's preview thumbnail (PNG).",
        examples=["/v1/examples/fig7_thin_film_cylinder_light/thumbnail.png"],
    )
