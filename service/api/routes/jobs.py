"""``/v1/jobs``: submit, list, inspect, follow (SSE), cancel and delete render jobs; list and download
their artifacts. Thin: the work happens in ``service.jobs`` and ``service.submissions``."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.responses import StreamingResponse
from sse_starlette import EventSourceResponse
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile

from hgcore.artifacts.keys import job_prefix
from hgcore.errors import InputError
from hgcore.jobs.status import JobStatus
from hgcore.jobs.views import JobView
from hgcore.noise_target import NoiseTarget
from hgcore.settings import SceneLimits
from hgcore.store.base import ArtifactNotFoundError, validate_key
from schemas import Scene
from service.api.deps import (
    AsyncRedisDep,
    JobId,
    JobsDep,
    Reader,
    SettingsDep,
    StoreDep,
    Submitter,
    ensure_visible,
    visible_job,
)
from service.api.openapi import JOB_ERRORS, form_fields_schema, problems, request_body
from service.events import job_events
from service.models import (
    ArtifactList,
    ArtifactView,
    JobCreate,
    JobCreated,
    JobList,
    JobOptions,
)
from service.submissions import scene_from_json, scene_from_upload

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])

_MULTIPART_SCHEMA = form_fields_schema(
    JobOptions,
    scene={"type": "string", "format": "binary", "description": ".json, .usda/.usdc/.usdz or .zip"},
)
_MULTIPART_EXAMPLE = {"scene": "scene.usda", "priority": "normal", "spp": 64, "chunks": 4, "name": "usd box"}


async def _parse_submission(
    request: Request, limits: SceneLimits
) -> tuple[Scene, dict[str, bytes], JobOptions]:
    """Body → (validated scene, bundle files, options); raises SceneError/ValidationError/ValueError."""
    content_type = request.headers.get("content-type", "")
    if content_type.startswith("multipart/form-data"):
        form = await request.form(max_files=1, max_fields=16)
        upload = form.get("scene")
        if not isinstance(upload, UploadFile):
            raise InputError("scene: multipart requests need a file field 'scene'")
        fields = {k: v for k, v in form.items() if k != "scene" and isinstance(v, str)}
        options = JobOptions.model_validate(fields, strict=False)  # form fields are text: '4' → 4
        content = await upload.read()
        scene, files = await run_in_threadpool(
            scene_from_upload, upload.filename or "", content, options, limits
        )
        return scene, files, options
    if not content_type.startswith("application/json"):
        raise InputError("content-type: send application/json or multipart/form-data")
    body = JobCreate.model_validate_json(await request.body())
    options = JobOptions.model_validate(body.model_dump(exclude={"scene"}))
    scene = await run_in_threadpool(scene_from_json, body.scene, options, limits)
    return scene, {}, options


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=JobCreated,
    summary="Submit a render job",
    responses={
        **JOB_ERRORS,
        200: {"model": JobCreated, "description": "An earlier job with the same idempotency_key."},
        **problems(
            request_entity_too_large="Body too large.",
            unprocessable_entity="Invalid request or scene; `errors` lists JSON pointers.",
        ),
    },
    openapi_extra=request_body(
        {
            # Inlined: the route reads the body itself (JSON or multipart), so FastAPI registers no
            # component for JobCreate. Its schema has no nested definitions to resolve.
            "application/json": {"schema": JobCreate.model_json_schema()},
            "multipart/form-data": {"schema": _MULTIPART_SCHEMA, "example": _MULTIPART_EXAMPLE},
        }
    ),
)
async def submit_job(
    request: Request, response: Response, jobs: JobsDep, settings: SettingsDep, principal: Submitter
) -> JobCreated:
    """Validate the scene (JSON body `{"scene": ...}` or a multipart file `scene`), store it, split it
    into chunks and enqueue them with a dependent merge step. Invalid input is rejected before anything
    is stored or enqueued."""
    scene, files, options = await _parse_submission(request, settings)  # a process's settings are its limits
    view, created = await run_in_threadpool(
        lambda: jobs.create(
            scene,
            principal.owner,
            priority=options.priority,
            chunks=options.chunks,
            noise_target=NoiseTarget.from_options(
                options.target_rel_error, options.time_budget_s, options.target_quantile
            ),
            idempotency_key=options.idempotency_key,
            name=options.name or scene.name,
            extra_files=files,
        )
    )
    if not created:
        response.status_code = status.HTTP_200_OK
    return JobCreated(id=view.id, status=view.status)


@router.get("", response_model=JobList, summary="List jobs", responses=JOB_ERRORS)
def list_jobs(
    jobs: JobsDep,
    principal: Reader,
    status_filter: Annotated[JobStatus | None, Query(alias="status")] = None,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
    limit: Annotated[int, Query(ge=1, le=200)] = 50,
) -> JobList:
    """Newest first; your own jobs (all jobs for admins), optionally of one status."""
    owner = None if principal.is_admin else principal.owner
    items, total = jobs.list(owner, status_filter, offset, limit)
    return JobList(items=items, total=total, offset=offset, limit=limit)


@router.get("/{job_id}", response_model=JobView, summary="Job status and progress", responses=JOB_ERRORS)
async def get_job(job_id: JobId, jobs: JobsDep, principal: Reader) -> Response:
    view = ensure_visible(await jobs.aget(job_id), principal, job_id)
    # Already a validated model: serialise once instead of FastAPI's re-validation of the return value.
    return Response(view.model_dump_json(), media_type="application/json")


@router.post(
    "/{job_id}/cancel",
    response_model=JobView,
    summary="Cancel a job",
    responses=JOB_ERRORS | problems(conflict="Job already finished."),
)
def cancel_job(job_id: JobId, jobs: JobsDep, principal: Submitter) -> JobView:
    """Queued chunks are dropped, running ones stop within seconds; the job reads `canceled`."""
    visible_job(jobs, principal, job_id)
    return jobs.cancel(job_id)


@router.delete(
    "/{job_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Delete a job and its artifacts",
    responses=JOB_ERRORS,
)
def delete_job(job_id: JobId, jobs: JobsDep, principal: Submitter) -> Response:
    visible_job(jobs, principal, job_id)
    jobs.delete(job_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# One Server-Sent Event (the form schemathesis and OpenAPI 3.2's `itemSchema` describe events in).
_SSE_EVENT_SCHEMA = {
    "type": "object",
    "required": ["event", "data"],
    "properties": {
        "event": {"type": "string", "enum": ["status", "progress"]},
        "data": {
            "type": "string",
            "contentMediaType": "application/json",
            "description": "`status`: the job view (as `GET /v1/jobs/{id}`); `progress`: `progress`, "
            "`chunks_done`, `chunks_total`, `eta_s`.",
        },
        "id": {"type": "string"},
        "retry": {"type": "integer"},
    },
}
_SSE_EXAMPLE = (
    'event: status\ndata: {"id": "3f2a...", "status": "running", "progress": 0.25, ...}\n\n'
    'event: progress\ndata: {"progress": 0.5, "chunks_done": 2, "chunks_total": 4, "eta_s": 3.1}\n\n'
)


@router.get(
    "/{job_id}/events",
    summary="Follow a job (Server-Sent Events)",
    response_class=EventSourceResponse,
    responses={
        **JOB_ERRORS,
        200: {
            "content": {"text/event-stream": {"schema": _SSE_EVENT_SCHEMA, "example": _SSE_EXAMPLE}},
            "description": "`status` and `progress` events (`data:` is JSON) until a final status.",
        },
    },
)
async def job_event_stream(
    request: Request, job_id: JobId, jobs: JobsDep, aredis: AsyncRedisDep, principal: Reader
) -> EventSourceResponse:
    """`status` events carry the full job view (first one immediately); `progress` events carry
    `progress`, `chunks_done`, `chunks_total`, `eta_s`. The stream ends after a final status."""
    await run_in_threadpool(visible_job, jobs, principal, job_id)
    return EventSourceResponse(job_events(request, aredis, jobs, job_id), ping=5)


@router.get(
    "/{job_id}/artifacts", response_model=ArtifactList, summary="List artifacts", responses=JOB_ERRORS
)
def list_artifacts(job_id: JobId, jobs: JobsDep, store: StoreDep, principal: Reader) -> ArtifactList:
    """Final artifacts (image.exr, preview.png, summary.json, worker.log, manifest.json, ...) and the
    job's inputs and chunk partials, with sizes and download URLs."""
    visible_job(jobs, principal, job_id)
    prefix = job_prefix(job_id)
    items = [
        ArtifactView(
            name=(name := info.key.removeprefix(prefix)),
            size_bytes=info.size_bytes,
            url=f"/v1/jobs/{job_id}/artifacts/{name}",
        )
        for info in store.list(prefix)
    ]
    return ArtifactList(job_id=job_id, items=items)


_MEDIA_TYPES = {".exr": "image/x-exr", ".png": "image/png", ".json": "application/json", ".log": "text/plain"}
_BINARY = {"schema": {"type": "string", "format": "binary"}}


@router.get(
    "/{job_id}/artifacts/{name:path}",
    summary="Download an artifact",
    response_class=StreamingResponse,
    responses={
        **JOB_ERRORS,
        200: {
            # Every type an artifact is sent as (by its suffix): image.exr/variance.exr are spectral
            # OpenEXR (`image/x-exr`), preview.png PNG, summary/manifest JSON, worker.log text, chunk
            # partials (.npz) and uploaded bundle files octet streams.
            "content": {
                media_type: _BINARY for media_type in (*_MEDIA_TYPES.values(), "application/octet-stream")
            },
            "description": "The file, as an attachment; its media type follows its suffix.",
        },
    },
)
def download_artifact(
    job_id: JobId, name: str, jobs: JobsDep, store: StoreDep, principal: Reader
) -> Response:
    visible_job(jobs, principal, job_id)
    try:
        key = validate_key(job_prefix(job_id) + name)
    except ValueError:
        raise ArtifactNotFoundError(name) from None  # reported without echoing the name
    media_type = _MEDIA_TYPES.get("." + name.rsplit(".", 1)[-1].lower(), "application/octet-stream")
    # Streamed from one open handle: an artifact replaced meanwhile (atomic rename) is sent whole, old
    # or new, never a mix (a separate stat for Content-Length could disagree with the bytes sent).
    pieces = store.iter_bytes(key)
    first = next(pieces, b"")  # raises ArtifactNotFoundError before the response starts

    def body() -> Any:
        yield first
        yield from pieces

    disposition = f'attachment; filename="{name.rsplit("/", 1)[-1]}"'
    return StreamingResponse(body(), media_type=media_type, headers={"Content-Disposition": disposition})
