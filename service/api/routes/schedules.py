"""``/v1/schedules``, ``/v1/runs`` and ``/v1/baselines``: regression schedules (create, list, get, pause,
resume, run now, delete), their run history with per-scene metric series, one-off runs of a suite, and
versioned scene baselines.
Thin: the work happens in ``service.regression``."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Query, Request, Response, status
from fastapi.responses import Response as RawResponse

from hgcore.jobs.records import JobNotFoundError
from service.api.deps import Reader, Submitter
from service.auth import Principal
from service.models import Problem
from service.regression.models import (
    BaselineList,
    BaselineView,
    PromoteRequest,
    RunCreate,
    RunList,
    RunView,
    ScheduleCreate,
    ScheduleList,
    ScheduleView,
    Suite,
)
from service.regression.runs import RunService
from service.regression.scheduler import next_run_times
from service.regression.store import (
    BASELINE_FILES,
    BaselineNotFoundError,
    RegressionStore,
    RunNotFoundError,
    ScheduleNotFoundError,
    run_series,
)

router = APIRouter(prefix="/v1", tags=["regression"])

ScheduleId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="Schedule id (32 hex digits).")]
RunId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="Run id (32 hex digits).")]
SceneName = Annotated[str, Path(pattern=r"^[A-Za-z0-9._-]{1,100}$", description="Scene key of a suite.")]
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": Problem, "description": "Missing or invalid token."},
    403: {"model": Problem, "description": "Token lacks the scope."},
    404: {"model": Problem, "description": "No such schedule, run or baseline (or another owner's)."},
}


def _runs(request: Request) -> RunService:
    state = request.app.state
    return RunService(state.jobs, RegressionStore(state.redis, state.store), state.settings)


def _schedule(runs: RunService, principal: Principal, schedule_id: str) -> ScheduleView:
    try:
        schedule = runs.regression.get_schedule(schedule_id)
    except ScheduleNotFoundError:
        schedule = None
    if schedule is None or not principal.can_see(schedule.owner):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"schedule_id: no schedule {schedule_id}")
    next_at = next_run_times(runs.jobs.client).get(schedule_id)
    return schedule.model_copy(update={"next_run_at": next_at})


def _run(runs: RunService, principal: Principal, run_id: str) -> RunView:
    try:
        run = runs.regression.get_run(run_id)
    except RunNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run_id: no run {run_id}") from None
    if not principal.can_see(run.owner):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run_id: no run {run_id}")
    return run


def _check_suite(runs: RunService, principal: Principal, suite: Suite) -> None:
    """Refuse a suite naming jobs the caller cannot see, or with a scene that does not validate."""
    for entry in suite.scenes:
        if entry.job_id is not None:
            view = runs.jobs.get(entry.job_id)
            if view is None or not principal.can_see(view.owner):
                raise JobNotFoundError(entry.job_id)
    runs.validate_suite(suite)


@router.post("/schedules", status_code=status.HTTP_201_CREATED, responses=_ERRORS, tags=["regression"])
def create_schedule(body: ScheduleCreate, request: Request, principal: Submitter) -> ScheduleView:
    """Create a schedule (its scenes are validated first); the scheduler picks it up within a second."""
    runs = _runs(request)
    _check_suite(runs, principal, body.suite)
    return runs.regression.create_schedule(body, principal.owner)


@router.get("/schedules", responses=_ERRORS)
def list_schedules(request: Request, principal: Reader) -> ScheduleList:
    runs = _runs(request)
    next_at = next_run_times(runs.jobs.client)
    items = [
        s.model_copy(update={"next_run_at": next_at.get(s.id)})
        for s in runs.regression.list_schedules()
        if principal.can_see(s.owner)
    ]
    return ScheduleList(items=items)


@router.get("/schedules/{schedule_id}", responses=_ERRORS)
def get_schedule(schedule_id: ScheduleId, request: Request, principal: Reader) -> ScheduleView:
    return _schedule(_runs(request), principal, schedule_id)


@router.delete("/schedules/{schedule_id}", status_code=status.HTTP_204_NO_CONTENT, responses=_ERRORS)
def delete_schedule(schedule_id: ScheduleId, request: Request, principal: Submitter) -> Response:
    """Delete the schedule (its runs and baselines stay)."""
    runs = _runs(request)
    _schedule(runs, principal, schedule_id)
    runs.regression.delete_schedule(schedule_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/schedules/{schedule_id}/pause", responses=_ERRORS)
def pause_schedule(schedule_id: ScheduleId, request: Request, principal: Submitter) -> ScheduleView:
    """Stop firing; due times during the pause are skipped."""
    runs = _runs(request)
    _schedule(runs, principal, schedule_id)
    return runs.regression.set_paused(schedule_id, True)


@router.post("/schedules/{schedule_id}/resume", responses=_ERRORS)
def resume_schedule(schedule_id: ScheduleId, request: Request, principal: Submitter) -> ScheduleView:
    runs = _runs(request)
    _schedule(runs, principal, schedule_id)
    return runs.regression.set_paused(schedule_id, False)


@router.post("/schedules/{schedule_id}/run", status_code=status.HTTP_202_ACCEPTED, responses=_ERRORS)
def run_schedule_now(schedule_id: ScheduleId, request: Request, principal: Submitter) -> RunView:
    """Start a run of the schedule's suite now (outside its timetable)."""
    runs = _runs(request)
    schedule = _schedule(runs, principal, schedule_id)
    return runs.start_run(
        schedule.suite,
        schedule.owner,
        trigger="manual",
        schedule_id=schedule_id,
        webhook_url=str(schedule.webhook_url) if schedule.webhook_url else None,
    )


@router.get("/schedules/{schedule_id}/runs", responses=_ERRORS)
def list_schedule_runs(
    schedule_id: ScheduleId,
    request: Request,
    principal: Reader,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> RunList:
    """Runs, newest first, and per-scene metric series (oldest first) for trend plots."""
    runs = _runs(request)
    _schedule(runs, principal, schedule_id)
    items = runs.regression.list_runs(schedule_id, limit)
    return RunList(items=items, series=run_series(items))


@router.post("/runs", status_code=status.HTTP_202_ACCEPTED, responses=_ERRORS)
def create_run(body: RunCreate, request: Request, principal: Submitter) -> RunView:
    """Run a suite once against the current baselines (no schedule); follow it with ``GET /v1/runs/{id}``."""
    runs = _runs(request)
    _check_suite(runs, principal, body.suite)
    return runs.start_run(
        body.suite,
        principal.owner,
        trigger="cli",
        webhook_url=str(body.webhook_url) if body.webhook_url else None,
    )


@router.get("/runs/{run_id}", responses=_ERRORS)
def get_run(run_id: RunId, request: Request, principal: Reader) -> RunView:
    return _run(_runs(request), principal, run_id)


@router.post("/baselines", status_code=status.HTTP_201_CREATED, responses=_ERRORS)
def promote_baseline(body: PromoteRequest, request: Request, principal: Submitter) -> list[BaselineView]:
    """Make a finished job (for ``scene``) or every scene of a finished run the new baseline version."""
    runs = _runs(request)
    if body.run_id is not None:
        run = _run(runs, principal, body.run_id)
        pairs = [(r.scene, r.job_id) for r in run.scenes if r.job_id]
    else:
        assert body.job_id is not None and body.scene is not None
        view = runs.jobs.get(body.job_id)
        if view is None or not principal.can_see(view.owner):
            raise JobNotFoundError(body.job_id)
        pairs = [(body.scene, body.job_id)]
    return [runs.regression.promote(scene, job_id, body.run_id) for scene, job_id in pairs]


@router.get("/baselines/{scene}", responses=_ERRORS)
def list_baselines(scene: SceneName, request: Request, principal: Reader) -> BaselineList:
    return _runs(request).regression.baselines(scene)


@router.post("/baselines/{scene}/current", responses=_ERRORS)
def set_current_baseline(
    scene: SceneName, request: Request, principal: Submitter, version: Annotated[int, Query(ge=1)]
) -> BaselineView:
    """Roll the scene's baseline back (or forward) to ``version``."""
    try:
        return _runs(request).regression.set_current_baseline(scene, version)
    except BaselineNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"version: {scene} has no v{version}") from None


@router.get("/baselines/{scene}/{version}/{name}", responses=_ERRORS)
def download_baseline_file(
    scene: SceneName, version: Annotated[int, Path(ge=1)], name: str, request: Request, principal: Reader
) -> RawResponse:
    if name not in BASELINE_FILES:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"name: must be one of {list(BASELINE_FILES)}")
    try:
        data = _runs(request).regression.baseline_file(scene, version, name)
    except BaselineNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"version: {scene} has no v{version}") from None
    media = "application/json" if name.endswith(".json") else "image/x-exr"
    return RawResponse(data, media_type=media)
