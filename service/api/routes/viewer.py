"""Viewer data endpoints: layer catalogue, raw float arrays of one layer, pixel records, the server-side
display image, coherence-ellipse grids, two-job differences, uploaded EXRs and the example scenes of the
submit form.

Thin, as the jobs routes: which image an id names is ``service.viewer_images``' policy, the work is in
``service.viewer_data`` (decoding runs in the thread pool), the examples are ``service.examples``'. Same
authentication and ownership rules as ``/v1/jobs`` (another owner's job is a 404).
"""

from __future__ import annotations

import json
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Path, Query, Request, Response
from starlette.concurrency import run_in_threadpool

from hgcore.image_metrics import map_statistics
from hgcore.imaging import TONE_MAPS
from service.api.deps import JobId, Reader, ViewerImagesDep
from service.api.openapi import AUTH_ERRORS, JOB_ERRORS, problems, request_body
from service.auth import Principal
from service.examples import example_document, example_scenes, thumbnail_png
from service.models import (
    Ellipse,
    EllipseGrid,
    ExampleScene,
    LayerCatalogue,
    LayerView,
    PixelView,
    UploadedImage,
)
from service.viewer_data import (
    COMPARE_MODES,
    DecodedImage,
    decode_uploaded_exr,
    diagnostics_exr,
    difference_map,
    display_png,
    ellipse_grid,
    encode_array,
    layer_array,
    pixel_record,
)
from service.viewer_images import ViewerImages

router = APIRouter(tags=["viewer"])
_IMAGE_ERRORS = JOB_ERRORS | problems(
    conflict="The job has no image yet (not finished).", unprocessable_entity="Invalid parameter."
)
_RAW = {200: {"content": {"application/octet-stream": {}}, "description": "Little-endian floats."}}
ExposureEV = Annotated[
    float, Query(ge=-64, le=64, allow_inf_nan=False, description="Exposure in stops: linear × 2^ev.")
]
ToneMap = Annotated[str, Query(pattern=f"^({'|'.join(TONE_MAPS)})$", description="clamp, reinhard or aces.")]


async def _image(images: ViewerImages, principal: Principal, job_id: str) -> DecodedImage:
    return await run_in_threadpool(images.image, job_id, principal)


async def _raw_array(values: np.ndarray, format: str, **headers: str) -> Response:
    """A float array as the body (row-major, little-endian ``format``; encoded in the thread pool) with
    its shape and ``headers`` in headers the browser may read."""
    exposed = {"X-Width": str(values.shape[1]), "X-Height": str(values.shape[0]), **headers}
    body = await run_in_threadpool(encode_array, values, format)
    return Response(
        body,
        media_type="application/octet-stream",
        headers={**exposed, "Access-Control-Expose-Headers": ", ".join(exposed)},
    )


@router.get(
    "/v1/jobs/{job_id}/layers",
    response_model=LayerCatalogue,
    summary="Layers of a job's image (names, units, wavelengths, ranges)",
    responses=_IMAGE_ERRORS,
)
async def list_layers(job_id: JobId, images: ViewerImagesDep, principal: Reader) -> LayerCatalogue:
    image = await _image(images, principal, job_id)
    layers = await run_in_threadpool(image.layers)
    return LayerCatalogue(
        job_id=job_id,
        partial=image.partial,
        spp=image.spp,
        uploaded=images.is_upload(job_id, principal),
        exposure_ev=await run_in_threadpool(image.exposure_ev),
        width=image.width,
        height=image.height,
        wavelengths_nm=image.wavelengths_nm,
        layers=[LayerView.model_validate(info, from_attributes=True) for info in layers],
    )


@router.get(
    "/v1/jobs/{job_id}/layers/{name}",
    summary="One layer as a raw little-endian float array",
    response_class=Response,
    responses={**_IMAGE_ERRORS, **_RAW},
)
async def get_layer(
    job_id: JobId,
    name: Annotated[str, Path(description="Layer name from /layers (`rgb`, `S0.555,000000nm`, ...).")],
    images: ViewerImagesDep,
    principal: Reader,
    format: Annotated[str, Query(pattern="^(f16|f32)$", description="f16 or f32.")] = "f32",
    step: Annotated[int, Query(ge=1, le=64, description="Downsampling factor.")] = 1,
) -> Response:
    """Row-major from the top-left pixel, channels interleaved (`rgb`: R, G, B). Headers `X-Width`,
    `X-Height`, `X-Channels`, `X-Format`. Bands and RGB are block means; other layers point samples."""
    image = await _image(images, principal, job_id)
    values = await run_in_threadpool(layer_array, image, name, step)
    channels = values.shape[2] if values.ndim == 3 else 1
    return await _raw_array(values, format, **{"X-Channels": str(channels), "X-Format": format})


@router.get(
    "/v1/jobs/{job_id}/pixel",
    response_model=PixelView,
    summary="Spectrum, RGB and coherence values of one pixel",
    responses=_IMAGE_ERRORS,
)
async def get_pixel(
    job_id: JobId,
    images: ViewerImagesDep,
    principal: Reader,
    x: Annotated[int, Query(ge=0, description="Column from the left.")],
    y: Annotated[int, Query(ge=0, description="Row from the top.")],
) -> PixelView:
    image = await _image(images, principal, job_id)
    return PixelView.model_validate(pixel_record(image, x, y))


@router.get(
    "/v1/jobs/{job_id}/display.png",
    summary="The sRGB image as the viewer displays it",
    response_class=Response,
    responses={**_IMAGE_ERRORS, 200: {"content": {"image/png": {}}, "description": "8-bit sRGB PNG."}},
)
async def get_display_png(
    job_id: JobId,
    images: ViewerImagesDep,
    principal: Reader,
    ev: ExposureEV = 0.0,
    tonemap: ToneMap = "clamp",
) -> Response:
    """`hgcore.imaging.display_rgb8(rgb, ev, tonemap)` of the full-resolution image."""
    image = await _image(images, principal, job_id)
    return Response(await run_in_threadpool(display_png, image, ev, tonemap), media_type="image/png")


@router.get(
    "/v1/jobs/{job_id}/diagnostics.exr",
    summary="The coherence diagnostics as an OpenEXR file",
    response_class=Response,
    responses={**_IMAGE_ERRORS, 200: {"content": {"image/x-exr": {}}, "description": "float32 EXR."}},
)
async def get_diagnostics_exr(job_id: JobId, images: ViewerImagesDep, principal: Reader) -> Response:
    """Every `coherence.*` channel of the image (ℓ₁, ℓ₂ in µm at 550 nm, angle in rad, anisotropy, area
    in µm², r in m, M in m⁻², weight), float32, the channel names of `image.exr`."""
    image = await _image(images, principal, job_id)
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
    job_id: JobId,
    images: ViewerImagesDep,
    principal: Reader,
    spacing: Annotated[int, Query(ge=2, le=4096, description="Grid spacing in pixels.")] = 16,
) -> EllipseGrid:
    """One ellipse per grid cell whose centre pixel has diagnostics (ℓ₁, ℓ₂ at λ = 550 nm)."""
    image = await _image(images, principal, job_id)
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
    images: ViewerImagesDep,
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
    two spectral images at exposure `ev` (`hgcore.image_metrics`, the code regression runs use). Headers
    `X-Width`, `X-Height`, `X-Stats` (JSON: mean, p95, max) and `X-Exposure-EV` (the EV used)."""
    image_a = await _image(images, principal, a)
    image_b = await _image(images, principal, b)
    exposure_ev = ev if ev is not None else await run_in_threadpool(image_a.exposure_ev)
    values = await run_in_threadpool(difference_map, image_a, image_b, mode, exposure_ev)
    statistics = json.dumps(map_statistics(values))
    return await _raw_array(values, format, **{"X-Stats": statistics, "X-Exposure-EV": repr(exposure_ev)})


@router.post(
    "/v1/images",
    response_model=UploadedImage,
    status_code=201,
    summary="View a spectral EXR from disk (drag and drop into the viewer)",
    responses=JOB_ERRORS
    | problems(
        request_entity_too_large="Larger than HGRENDER_MAX_REQUEST_BYTES.",
        unprocessable_entity="Not an OpenEXR file, or fewer than 2 S0.<λ>nm channels.",
    ),
    openapi_extra=request_body(
        {
            # The body is read as raw bytes whatever its type (image/x-exr too); one type is listed
            # because the example must be serialisable. A real body is a file's bytes (e.g. a job's
            # image.exr); this placeholder gets a 422.
            "application/octet-stream": {
                "schema": {"type": "string", "format": "binary"},
                "example": "<the bytes of a spectral OpenEXR file such as a job's image.exr>",
            }
        }
    ),
)
async def upload_image(request: Request, images: ViewerImagesDep, principal: Reader) -> UploadedImage:
    """The body is the EXR file itself. It is decoded with OpenImageIO, checked to carry at least two
    spectral `S0.<λ>nm` channels, and kept in the service's memory only (the last 4 uploads; nothing is
    stored): the returned id works with every viewer endpoint for its uploader. Size bounded by the
    request limit (413)."""
    data = await request.body()
    image = await run_in_threadpool(decode_uploaded_exr, data)
    return UploadedImage(
        id=images.upload(principal.owner, image),
        width=image.width,
        height=image.height,
        wavelengths_nm=image.wavelengths_nm,
    )


_EXAMPLE_ERRORS = AUTH_ERRORS | problems(not_found="No such example scene (or thumbnail).")


@router.get(
    "/v1/examples", response_model=list[ExampleScene], summary="Example scenes", responses=AUTH_ERRORS
)
def list_examples(principal: Reader) -> list[ExampleScene]:
    """The scenes in `schemas/examples/` (each renders as is): the gallery's first, in its order, with their
    figure, view and thumbnail; then the others by name."""
    return example_scenes()


@router.get(
    "/v1/examples/{stem}/thumbnail.png",
    summary="A gallery scene's thumbnail",
    responses={**_EXAMPLE_ERRORS, 200: {"content": {"image/png": {}}}},
    response_class=Response,
)
def get_example_thumbnail(
    stem: Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]+$")], principal: Reader
) -> Response:
    return Response(thumbnail_png(stem), media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.get("/v1/examples/{name}", summary="One example scene (JSON)", responses=_EXAMPLE_ERRORS)
def get_example(
    name: Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]+\.json$")], principal: Reader
) -> dict[str, Any]:
    return example_document(name)
