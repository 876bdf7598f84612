"""``/v1/schedules``, ``/v1/runs`` and ``/v1/baselines``: regression schedules (create, list, get, pause,
resume, run now, delete), their run history with per-scene metric series, one-off runs of a suite, and
versioned scene baselines.
Thin: the work happens in ``service.regression``."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response, status
from fastapi.responses import Response as RawResponse

from hgcore.jobs.lifecycle import JobNotFoundError
from hgcore.regression.models import (
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
from hgcore.regression.store import (
    BASELINE_FILES,
    BaselineNotFoundError,
    RegressionStore,
    RunNotFoundError,
    ScheduleNotFoundError,
    run_series,
)
from service.api.deps import JobsDep, Reader, RedisDep, SettingsDep, StoreDep, Submitter
from service.api.openapi import AUTH_ERRORS, problems
from service.auth import Principal
from service.regression.runs import RunService
from service.regression.scheduler import next_run_times

router = APIRouter(prefix="/v1", tags=["regression"])

ScheduleId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="Schedule id (32 hex digits).")]
RunId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="Run id (32 hex digits).")]
SceneName = Annotated[str, Path(pattern=r"^[A-Za-z0-9._-]{1,100}$", description="Scene key of a suite.")]
_ERRORS = AUTH_ERRORS | problems(not_found="No such schedule, run or baseline (or another owner's).")


def _runs(jobs: JobsDep, client: RedisDep, store: StoreDep, settings: SettingsDep) -> RunService:
    return RunService(jobs, RegressionStore(client, store), settings)


RunsDep = Annotated[RunService, Depends(_runs)]


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
def create_schedule(body: ScheduleCreate, runs: RunsDep, principal: Submitter) -> ScheduleView:
    """Create a schedule (its scenes are validated first); the scheduler picks it up within a second."""
    _check_suite(runs, principal, body.suite)
    return runs.regression.create_schedule(body, principal.owner)


@router.get("/schedules", responses=_ERRORS)
def list_schedules(runs: RunsDep, principal: Reader) -> ScheduleList:
    next_at = next_run_times(runs.jobs.client)
    items = [
        s.model_copy(update={"next_run_at": next_at.get(s.id)})
        for s in runs.regression.list_schedules()
        if principal.can_see(s.owner)
    ]
    return ScheduleList(items=items)


@router.get("/schedules/{schedule_id}", responses=_ERRORS)
def get_schedule(schedule_id: ScheduleId, runs: RunsDep, principal: Reader) -> ScheduleView:
    return _schedule(runs, principal, schedule_id)


@router.delete("/schedules/{schedule_id}", status_code=status.HTTP_204_NO_CONTENT, responses=_ERRORS)
def delete_schedule(schedule_id: ScheduleId, runs: RunsDep, principal: Submitter) -> Response:
    """Delete the schedule (its runs and baselines stay)."""
    _schedule(runs, principal, schedule_id)
    runs.regression.delete_schedule(schedule_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/schedules/{schedule_id}/pause", responses=_ERRORS)
def pause_schedule(schedule_id: ScheduleId, runs: RunsDep, principal: Submitter) -> ScheduleView:
    """Stop firing; due times during the pause are skipped."""
    _schedule(runs, principal, schedule_id)
    return runs.regression.set_paused(schedule_id, True)


@router.post("/schedules/{schedule_id}/resume", responses=_ERRORS)
def resume_schedule(schedule_id: ScheduleId, runs: RunsDep, principal: Submitter) -> ScheduleView:
    _schedule(runs, principal, schedule_id)
    return runs.regression.set_paused(schedule_id, False)


@router.post("/schedules/{schedule_id}/run", status_code=status.HTTP_202_ACCEPTED, responses=_ERRORS)
def run_schedule_now(schedule_id: ScheduleId, runs: RunsDep, principal: Submitter) -> RunView:
    """Start a run of the schedule's suite now (outside its timetable)."""
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
    runs: RunsDep,
    principal: Reader,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> RunList:
    """Runs, newest first, and per-scene metric series (oldest first) for trend plots."""
    _schedule(runs, principal, schedule_id)
    items = runs.regression.list_runs(schedule_id, limit)
    return RunList(items=items, series=run_series(items))


@router.post("/runs", status_code=status.HTTP_202_ACCEPTED, responses=_ERRORS)
def create_run(body: RunCreate, runs: RunsDep, principal: Submitter) -> RunView:
    """Run a suite once against the current baselines (no schedule); follow it with ``GET /v1/runs/{id}``."""
    _check_suite(runs, principal, body.suite)
    return runs.start_run(
        body.suite,
        principal.owner,
        trigger="cli",
        webhook_url=str(body.webhook_url) if body.webhook_url else None,
    )


@router.get("/runs/{run_id}", responses=_ERRORS)
def get_run(run_id: RunId, runs: RunsDep, principal: Reader) -> RunView:
    return _run(runs, principal, run_id)


@router.post("/baselines", status_code=status.HTTP_201_CREATED, responses=_ERRORS)
def promote_baseline(body: PromoteRequest, runs: RunsDep, principal: Submitter) -> list[BaselineView]:
    """Make a finished job (for ``scene``) or every scene of a finished run the new baseline version."""
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
def list_baselines(scene: SceneName, runs: RunsDep, principal: Reader) -> BaselineList:
    return runs.regression.baselines(scene)


@router.post("/baselines/{scene}/current", responses=_ERRORS)
def set_current_baseline(
    scene: SceneName, runs: RunsDep, principal: Submitter, version: Annotated[int, Query(ge=1)]
) -> BaselineView:
    """Roll the scene's baseline back (or forward) to ``version``."""
    try:
        return runs.regression.set_current_baseline(scene, version)
    except BaselineNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"version: {scene} has no v{version}") from None


@router.get("/baselines/{scene}/{version}/{name}", responses=_ERRORS)
def download_baseline_file(
    scene: SceneName, version: Annotated[int, Path(ge=1)], name: str, runs: RunsDep, principal: Reader
) -> RawResponse:
    if name not in BASELINE_FILES:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"name: must be one of {list(BASELINE_FILES)}")
    try:
        data = runs.regression.baseline_file(scene, version, name)
    except BaselineNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"version: {scene} has no v{version}") from None
    media = "application/json" if name.endswith(".json") else "image/x-exr"
    return RawResponse(data, media_type=media)
