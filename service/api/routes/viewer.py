"""Viewer data endpoints: layer catalogue, raw float arrays of one layer, pixel records, the server-side
display image, coherence-ellipse grids, two-job differences and the example scenes of the submit form.

Thin: the work is in ``service.viewer_data``; decoding runs in the thread pool. Same authentication and
ownership rules as ``/v1/jobs`` (another owner's job is a 404). ``install(app)`` adds the router and the
decoded-image cache (``app.state.viewer_images``).
"""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, FastAPI, Path, Query, Response
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request

from hgcore.imaging import TONE_MAPS
from hgcore.jobs.status import JobStatus
from hgcore.store.base import ArtifactNotFoundError
from schemas import EXAMPLES_DIR
from schemas.gallery import GALLERY_BY_NAME, THUMBNAILS_DIR, GalleryView
from service.api.deps import JobsDep, Reader, visible_job
from service.api.routes.jobs import _ERRORS, JobId
from service.image_metrics import map_statistics
from service.jobs import JobConflictError
from service.models import Problem
from service.viewer_data import (
    COMPARE_MODES,
    DecodedImage,
    DecodedImageCache,
    LayerInfo,
    UploadedImages,
    decode_uploaded_exr,
    diagnostics_exr,
    difference_map,
    display_png,
    ellipse_grid,
    encode_array,
    layer_array,
    pixel_record,
)

router = APIRouter(tags=["viewer"])
_IMAGE_ERRORS: dict[int | str, dict[str, Any]] = {
    **_ERRORS,
    409: {"model": Problem, "description": "The job has no image yet (not finished)."},
    422: {"model": Problem, "description": "Invalid parameter."},
}
_RAW = {200: {"content": {"application/octet-stream": {}}, "description": "Little-endian floats."}}
ExposureEV = Annotated[
    float, Query(ge=-64, le=64, allow_inf_nan=False, description="Exposure in stops: linear × 2^ev.")
]
ToneMap = Annotated[str, Query(pattern=f"^({'|'.join(TONE_MAPS)})$", description="clamp, reinhard or aces.")]


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


def install(app: FastAPI, max_images: int = 8, max_uploads: int = 4) -> None:
    """Add the viewer routes, their decoded-image cache and the in-memory uploaded images to ``app``."""
    app.state.viewer_images = DecodedImageCache(app.state.store, max_images)
    app.state.viewer_uploads = UploadedImages(max_uploads)
    app.include_router(router)


async def _image(request: Request, jobs: JobsDep, principal: Reader, job_id: str) -> DecodedImage:
    uploads: UploadedImages = request.app.state.viewer_uploads
    uploaded = uploads.get(job_id, principal.can_see)
    if uploaded is not None:
        return uploaded
    view = await run_in_threadpool(visible_job, jobs, principal, job_id)
    cache: DecodedImageCache = request.app.state.viewer_images
    if view.status == JobStatus.SUCCEEDED:
        return await run_in_threadpool(cache.get, job_id)
    if view.status == JobStatus.RUNNING:
        # A running job shows the chunks finished so far (issue 6: "where partial results exist").
        film = (await run_in_threadpool(jobs.scene, job_id))["film"]  # validated: every field present
        # A noise-target job replaces its one partial after each round: the round count tells them apart.
        revision = len(view.noise_target.rounds or []) if view.noise_target is not None else 0
        try:
            return await run_in_threadpool(cache.get_partial, job_id, film, revision)
        except ArtifactNotFoundError:
            pass
    raise JobConflictError(
        f"job_id: job {job_id} is {view.status.value}; its image exists once a chunk has finished"
    )


def _layer_view(info: LayerInfo) -> LayerView:
    return LayerView.model_validate(info, from_attributes=True)


@router.get(
    "/v1/jobs/{job_id}/layers",
    response_model=LayerCatalogue,
    summary="Layers of a job's image (names, units, wavelengths, ranges)",
    responses=_IMAGE_ERRORS,
)
async def list_layers(request: Request, job_id: JobId, jobs: JobsDep, principal: Reader) -> LayerCatalogue:
    image = await _image(request, jobs, principal, job_id)
    layers = await run_in_threadpool(image.layers)
    uploads: UploadedImages = request.app.state.viewer_uploads
    return LayerCatalogue(
        job_id=job_id,
        partial=image.partial,
        spp=image.spp,
        uploaded=uploads.get(job_id, principal.can_see) is not None,
        exposure_ev=await run_in_threadpool(image.exposure_ev),
        width=image.width,
        height=image.height,
        wavelengths_nm=image.wavelengths_nm,
        layers=[_layer_view(info) for info in layers],
    )


@router.get(
    "/v1/jobs/{job_id}/layers/{name}",
    summary="One layer as a raw little-endian float array",
    response_class=Response,
    responses={**_IMAGE_ERRORS, **_RAW},
)
async def get_layer(
    request: Request,
    job_id: JobId,
    name: Annotated[str, Path(description="Layer name from /layers (`rgb`, `S0.555,000000nm`, ...).")],
    jobs: JobsDep,
    principal: Reader,
    format: Annotated[str, Query(pattern="^(f16|f32)$", description="f16 or f32.")] = "f32",
    step: Annotated[int, Query(ge=1, le=64, description="Downsampling factor.")] = 1,
) -> Response:
    """Row-major from the top-left pixel, channels interleaved (`rgb`: R, G, B). Headers `X-Width`,
    `X-Height`, `X-Channels`, `X-Format`. Bands and RGB are block means; other layers point samples."""
    image = await _image(request, jobs, principal, job_id)
    values = await run_in_threadpool(layer_array, image, name, step)
    channels = values.shape[2] if values.ndim == 3 else 1
    headers = {
        "X-Width": str(values.shape[1]),
        "X-Height": str(values.shape[0]),
        "X-Channels": str(channels),
        "X-Format": format,
        "Access-Control-Expose-Headers": "X-Width, X-Height, X-Channels, X-Format",
    }
    body = await run_in_threadpool(encode_array, values, format)
    return Response(body, media_type="application/octet-stream", headers=headers)


@router.get(
    "/v1/jobs/{job_id}/pixel",
    response_model=PixelView,
    summary="Spectrum, RGB and coherence values of one pixel",
    responses=_IMAGE_ERRORS,
)
async def get_pixel(
    request: Request,
    job_id: JobId,
    jobs: JobsDep,
    principal: Reader,
    x: Annotated[int, Query(ge=0, description="Column from the left.")],
    y: Annotated[int, Query(ge=0, description="Row from the top.")],
) -> PixelView:
    image = await _image(request, jobs, principal, job_id)
    return PixelView.model_validate(pixel_record(image, x, y))


@router.get(
    "/v1/jobs/{job_id}/display.png",
    summary="The sRGB image as the viewer displays it",
    response_class=Response,
    responses={**_IMAGE_ERRORS, 200: {"content": {"image/png": {}}, "description": "8-bit sRGB PNG."}},
)
async def get_display_png(
    request: Request,
    job_id: JobId,
    jobs: JobsDep,
    principal: Reader,
    ev: ExposureEV = 0.0,
    tonemap: ToneMap = "clamp",
) -> Response:
    """`hgcore.imaging.display_rgb8(rgb, ev, tonemap)` of the full-resolution image."""
    image = await _image(request, jobs, principal, job_id)
    return Response(await run_in_threadpool(display_png, image, ev, tonemap), media_type="image/png")


@router.get(
    "/v1/jobs/{job_id}/diagnostics.exr",
    summary="The coherence diagnostics as an OpenEXR file",
    response_class=Response,
    responses={**_IMAGE_ERRORS, 200: {"content": {"image/x-exr": {}}, "description": "float32 EXR."}},
)
async def get_diagnostics_exr(request: Request, job_id: JobId, jobs: JobsDep, principal: Reader) -> Response:
    """Every `coherence.*` channel of the image (ℓ₁, ℓ₂ in µm at 550 nm, angle in rad, anisotropy, area
    in µm², r in m, M in m⁻², weight), float32, the channel names of `image.exr`."""
    image = await _image(request, jobs, principal, job_id)
    body = await run_in_threadpool(diagnostics_exr, image)
    disposition = f'attachment; filename="{job_id}_diagnostics.exr"'
    return Response(body, media_type="image/x-exr", headers={"Content-Disposition": disposition})


@router.get(
    "/v1/jobs/{job_id}/ellipses",
    response_model=EllipseGrid,
    summary="Coherence ellipses on a grid",
    responses=_IMAGE_ERRORS,
)
async def get_ellipses(
    request: Request,
    job_id: JobId,
    jobs: JobsDep,
    principal: Reader,
    spacing: Annotated[int, Query(ge=2, le=4096, description="Grid spacing in pixels.")] = 16,
) -> EllipseGrid:
    """One ellipse per grid cell whose centre pixel has diagnostics (ℓ₁, ℓ₂ at λ = 550 nm)."""
    image = await _image(request, jobs, principal, job_id)
    grid = await run_in_threadpool(ellipse_grid, image, spacing)
    return EllipseGrid(
        job_id=job_id,
        width=image.width,
        height=image.height,
        spacing=spacing,
        ellipses=[Ellipse.model_validate(e) for e in grid],
    )


@router.get(
    "/v1/compare",
    summary="Per-pixel difference of two jobs' images",
    response_class=Response,
    responses={**_IMAGE_ERRORS, **_RAW},
)
async def compare_jobs(
    request: Request,
    jobs: JobsDep,
    principal: Reader,
    a: Annotated[str, Query(pattern=r"^[0-9a-f]{32}$", description="Reference job id.")],
    b: Annotated[str, Query(pattern=r"^[0-9a-f]{32}$", description="Compared job id.")],
    mode: Annotated[
        str, Query(pattern=f"^({'|'.join(COMPARE_MODES)})$", description="abs, rel, de2000 or flip.")
    ],
    ev: Annotated[
        float | None,
        Query(ge=-64, le=64, description="Exposure of de2000/flip (EV); default: a's automatic exposure."),
    ] = None,
    format: Annotated[str, Query(pattern="^(f16|f32)$")] = "f32",
) -> Response:
    """Float (H, W) map, row-major from the top-left: `abs` = mean |b − a| over linear R, G, B; `rel` =
    the same over max(|a|, 1 % of a's mean luminance); `de2000` = CIEDE2000 ΔE₀₀ and `flip` = ꟻLIP of the
    two spectral images at exposure `ev` (`service.image_metrics`, the code regression runs use). Headers
    `X-Width`, `X-Height`, `X-Stats` (JSON: mean, p95, max) and `X-Exposure-EV` (the EV used)."""
    image_a = await _image(request, jobs, principal, a)
    image_b = await _image(request, jobs, principal, b)
    exposure_ev = ev if ev is not None else await run_in_threadpool(image_a.exposure_ev)
    values = await run_in_threadpool(difference_map, image_a, image_b, mode, exposure_ev)
    headers = {
        "X-Width": str(values.shape[1]),
        "X-Height": str(values.shape[0]),
        "X-Stats": json.dumps(map_statistics(values)),
        "X-Exposure-EV": repr(exposure_ev),
        "Access-Control-Expose-Headers": "X-Width, X-Height, X-Stats, X-Exposure-EV",
    }
    return Response(encode_array(values, format), media_type="application/octet-stream", headers=headers)


@router.post(
    "/v1/images",
    response_model=UploadedImage,
    status_code=201,
    summary="View a spectral EXR from disk (drag and drop into the viewer)",
    responses={
        **_ERRORS,
        413: {"model": Problem, "description": "Larger than HGRENDER_MAX_REQUEST_BYTES."},
        422: {"model": Problem, "description": "Not an OpenEXR file, or fewer than 2 S0.<λ>nm channels."},
    },
    openapi_extra={
        "requestBody": {
            "required": True,
            "content": {
                # The body is read as raw bytes whatever its type (image/x-exr too); one type is listed
                # because the example must be serialisable. A real body is a file's bytes (e.g. a job's
                # image.exr); this placeholder gets a 422.
                "application/octet-stream": {
                    "schema": {"type": "string", "format": "binary"},
                    "example": "<the bytes of a spectral OpenEXR file such as a job's image.exr>",
                }
            },
        }
    },
)
async def upload_image(request: Request, principal: Reader) -> UploadedImage:
    """The body is the EXR file itself. It is decoded with OpenImageIO, checked to carry at least two
    spectral `S0.<λ>nm` channels, and kept in the service's memory only (the last 4 uploads; nothing is
    stored): the returned id works with every viewer endpoint for its uploader. Size bounded by the
    request limit (413)."""
    data = await request.body()
    image = await run_in_threadpool(decode_uploaded_exr, data)
    uploads: UploadedImages = request.app.state.viewer_uploads
    return UploadedImage(
        id=uploads.add(principal.owner, image),
        width=image.width,
        height=image.height,
        wavelengths_nm=image.wavelengths_nm,
    )


@router.get("/v1/examples", response_model=list[ExampleScene], summary="Example scenes", responses=_ERRORS)
def list_examples(principal: Reader) -> list[ExampleScene]:
    """The scenes in `schemas/examples/` (each renders as is): the gallery's first, in its order, with their
    figure, view and thumbnail; then the others by name."""
    examples = []
    for path in sorted(EXAMPLES_DIR.glob("*.json")):
        title = json.loads(path.read_text()).get("name", path.stem)
        entry = GALLERY_BY_NAME.get(path.stem)
        if entry is None:
            examples.append(ExampleScene(name=path.name, title=title))
            continue
        has_thumbnail = (THUMBNAILS_DIR / f"{path.stem}.png").is_file()
        examples.append(
            ExampleScene(
                name=path.name,
                title=title,
                figure=entry.figure,
                view=entry.viewer_view,
                thumbnail=f"/v1/examples/{path.stem}/thumbnail.png" if has_thumbnail else None,
            )
        )
    order = list(GALLERY_BY_NAME)
    return sorted(examples, key=lambda e: (order.index(e.name[:-5]) if e.figure else len(order), e.name))


@router.get(
    "/v1/examples/{stem}/thumbnail.png",
    summary="A gallery scene's thumbnail",
    responses={**_ERRORS, 200: {"content": {"image/png": {}}}},
    response_class=Response,
)
def get_example_thumbnail(
    stem: Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]+$")], principal: Reader
) -> Response:
    path = THUMBNAILS_DIR / f"{stem}.png"
    if stem not in GALLERY_BY_NAME or not path.is_file():
        raise ArtifactNotFoundError(f"{stem}/thumbnail.png")
    return Response(path.read_bytes(), media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.get("/v1/examples/{name}", summary="One example scene (JSON)", responses=_ERRORS)
def get_example(
    name: Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]+\.json$")], principal: Reader
) -> dict[str, Any]:
    path = EXAMPLES_DIR / name
    if not path.is_file():
        raise ArtifactNotFoundError(name)
    return json.loads(path.read_text())
