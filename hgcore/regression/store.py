"""Persistence of schedules, runs and baselines: records in Redis, baseline images in the artifact store.

Redis layout (all under ``hgrender:regression:``):

``schedule:<id>``              JSON of the ScheduleView (without ``next_run_at``)
``schedules``                  sorted set of schedule ids by creation time
``schedules:version``          counter bumped on every change (the scheduler re-syncs when it moves)
``fired:<schedule>:<due>``     claim of one due time (SET NX): the run of that due time exists exactly once
``run:<id>``                   JSON of the RunView
``runs`` / ``runs:schedule:<id>``  sorted sets of run ids by creation time
``baseline:<scene>``           hash: ``current`` version, ``next`` counter, ``v<N>`` JSON of each BaselineView

Baseline version N of a scene is a copy of the job's ``image.exr``, ``variance.exr`` and ``summary.json`` at
``baselines/<scene>/v<N>/`` in the artifact store, so deleting the job keeps the baseline.
"""

from __future__ import annotations

import time
import uuid

import redis

from hgcore.artifacts.keys import job_prefix
from hgcore.artifacts.layout import IMAGE_EXR, SUMMARY_JSON, VARIANCE_EXR
from hgcore.errors import InputError
from hgcore.regression.models import BaselineList, BaselineView, RunView, ScheduleCreate, ScheduleView
from hgcore.store.base import ArtifactNotFoundError, ArtifactStore

_PREFIX = "hgrender:regression:"
_SCHEDULE_KEY = _PREFIX + "schedule:{}"
_SCHEDULES_KEY = _PREFIX + "schedules"
_VERSION_KEY = _PREFIX + "schedules:version"
_FIRED_KEY = _PREFIX + "fired:{}:{}"
_RUN_KEY = _PREFIX + "run:{}"
_RUNS_KEY = _PREFIX + "runs"
_SCHEDULE_RUNS_KEY = _PREFIX + "runs:schedule:{}"
_BASELINE_KEY = _PREFIX + "baseline:{}"

BASELINE_FILES: tuple[str, ...] = (IMAGE_EXR, VARIANCE_EXR, SUMMARY_JSON)
FIRED_CLAIM_TTL_S = 90 * 24 * 3600
_CLAIM_LUA = """
local holder = redis.call('GET', KEYS[1])
if not holder then redis.call('SET', KEYS[1], ARGV[1], 'EX', ARGV[2]) return 1 end
if holder == ARGV[1] then return 1 end
return 0
"""
"""How long a due-time claim is kept (longer than any misfire grace, so a claim outlives every retry)."""


class ScheduleNotFoundError(KeyError):
    """No schedule with this id."""


class RunNotFoundError(KeyError):
    """No run with this id."""


class BaselineNotFoundError(KeyError):
    """The scene has no baseline (of this version)."""


def baseline_prefix(scene: str, version: int) -> str:
    return f"baselines/{scene}/v{version}/"


class RegressionStore:
    """Schedules, runs and baselines of one deployment."""

    def __init__(self, client: redis.Redis, store: ArtifactStore) -> None:
        self.client = client
        self.store = store
        self._claim = client.register_script(_CLAIM_LUA)

    # ---- schedules ------------------------------------------------------------------------------------

    def create_schedule(self, request: ScheduleCreate, owner: str) -> ScheduleView:
        view = ScheduleView(**request.model_dump(), id=uuid.uuid4().hex, owner=owner, created_at=time.time())
        self._save_schedule(view, new=True)
        return view

    def _save_schedule(self, view: ScheduleView, new: bool = False) -> None:
        with self.client.pipeline() as pipe:
            pipe.set(_SCHEDULE_KEY.format(view.id), view.model_dump_json(exclude={"next_run_at"}))
            if new:
                pipe.zadd(_SCHEDULES_KEY, {view.id: view.created_at})
            pipe.incr(_VERSION_KEY)
            pipe.execute()

    def get_schedule(self, schedule_id: str) -> ScheduleView:
        raw = self.client.get(_SCHEDULE_KEY.format(schedule_id))
        if raw is None:
            raise ScheduleNotFoundError(schedule_id)
        return ScheduleView.model_validate_json(raw)

    def list_schedules(self) -> list[ScheduleView]:
        ids = [i.decode() for i in self.client.zrange(_SCHEDULES_KEY, 0, -1)]
        raws = self.client.mget([_SCHEDULE_KEY.format(i) for i in ids]) if ids else []
        return [ScheduleView.model_validate_json(raw) for raw in raws if raw is not None]

    def set_paused(self, schedule_id: str, paused: bool) -> ScheduleView:
        view = self.get_schedule(schedule_id).model_copy(update={"paused": paused})
        self._save_schedule(view)
        return view

    def delete_schedule(self, schedule_id: str) -> None:
        self.get_schedule(schedule_id)
        with self.client.pipeline() as pipe:
            pipe.delete(_SCHEDULE_KEY.format(schedule_id))
            pipe.zrem(_SCHEDULES_KEY, schedule_id)
            pipe.incr(_VERSION_KEY)
            pipe.execute()

    def schedules_version(self) -> int:
        return int(self.client.get(_VERSION_KEY) or 0)

    def claim_due_time(self, schedule_id: str, due_at: float, claimer: str = "") -> bool:
        """True for exactly one ``claimer`` per (schedule, due time): the one that must create its run.
        The same claimer asking again is told True again, so a claim whose reply a Redis outage lost can
        be retried (``claimer``: the scheduler's unique name; "" claims anonymously, once)."""
        key = _FIRED_KEY.format(schedule_id, f"{due_at:.3f}")
        if not claimer:
            return bool(self.client.set(key, "1", nx=True, ex=FIRED_CLAIM_TTL_S))
        return bool(self._claim(keys=[key], args=[claimer, FIRED_CLAIM_TTL_S]))

    # ---- runs -----------------------------------------------------------------------------------------

    def save_run(self, run: RunView) -> None:
        with self.client.pipeline() as pipe:
            pipe.set(_RUN_KEY.format(run.id), run.model_dump_json())
            pipe.zadd(_RUNS_KEY, {run.id: run.created_at})
            if run.schedule_id is not None:
                pipe.zadd(_SCHEDULE_RUNS_KEY.format(run.schedule_id), {run.id: run.created_at})
            pipe.execute()

    def get_run(self, run_id: str) -> RunView:
        raw = self.client.get(_RUN_KEY.format(run_id))
        if raw is None:
            raise RunNotFoundError(run_id)
        return RunView.model_validate_json(raw)

    def list_runs(self, schedule_id: str | None = None, limit: int = 100) -> list[RunView]:
        """Newest first."""
        key = _SCHEDULE_RUNS_KEY.format(schedule_id) if schedule_id is not None else _RUNS_KEY
        ids = [i.decode() for i in self.client.zrevrange(key, 0, limit - 1)]
        raws = self.client.mget([_RUN_KEY.format(i) for i in ids]) if ids else []
        return [RunView.model_validate_json(raw) for raw in raws if raw is not None]

    # ---- baselines ------------------------------------------------------------------------------------

    def promote(self, scene: str, job_id: str, run_id: str | None = None) -> BaselineView:
        """Copy a finished job's images to the next baseline version of ``scene`` and make it current."""
        source = job_prefix(job_id)
        available = {info.key.removeprefix(source) for info in self.store.list(source)}
        missing = [name for name in BASELINE_FILES if name not in available]
        if missing:
            raise InputError(f"job_id: job {job_id} has no {', '.join(missing)} (not a finished render)")
        version = int(self.client.hincrby(_BASELINE_KEY.format(scene), "next", 1))
        for name in BASELINE_FILES:
            self.store.put_bytes(baseline_prefix(scene, version) + name, self.store.get_bytes(source + name))
        view = BaselineView(
            scene=scene,
            version=version,
            job_id=job_id,
            run_id=run_id,
            created_at=time.time(),
            files=list(BASELINE_FILES),
        )
        # Current moves only after the files are in place: a comparison never sees a partial baseline.
        self.client.hset(
            _BASELINE_KEY.format(scene), mapping={f"v{version}": view.model_dump_json(), "current": version}
        )
        return view

    def baselines(self, scene: str) -> BaselineList:
        fields = {k.decode(): v.decode() for k, v in self.client.hgetall(_BASELINE_KEY.format(scene)).items()}
        versions = sorted(
            (BaselineView.model_validate_json(v) for k, v in fields.items() if k.startswith("v")),
            key=lambda view: view.version,
        )
        current = int(fields["current"]) if "current" in fields else None
        return BaselineList(scene=scene, current=current, versions=versions)

    def current_baseline(self, scene: str) -> BaselineView | None:
        listing = self.baselines(scene)
        return next((v for v in listing.versions if v.version == listing.current), None)

    def set_current_baseline(self, scene: str, version: int) -> BaselineView:
        """Make an earlier version current again (roll back)."""
        view = next((v for v in self.baselines(scene).versions if v.version == version), None)
        if view is None:
            raise BaselineNotFoundError(f"{scene} v{version}")
        self.client.hset(_BASELINE_KEY.format(scene), "current", version)
        return view

    def baseline_file(self, scene: str, version: int, name: str) -> bytes:
        try:
            return self.store.get_bytes(baseline_prefix(scene, version) + name)
        except ArtifactNotFoundError:
            raise BaselineNotFoundError(f"{scene} v{version} {name}") from None


def run_series(runs: list[RunView]) -> dict[str, list[dict[str, object]]]:
    """Per-scene history (oldest first) of the runs' headline metrics, for trend plots: the quantities the
    verdict compares with thresholds (``*_excess``, ``rel_rmse_max``), the raw ΔE₀₀ p95 and ꟻLIP mean, and
    the exposure the colour metrics used (the dashboard opens the compare view at it)."""
    series: dict[str, list[dict[str, object]]] = {}
    for run in sorted(runs, key=lambda r: r.created_at):
        for result in run.scenes:
            if result.verdict is None:
                continue
            delta_e = result.metrics.get("delta_e00", {})
            flip = result.metrics.get("flip", {})
            series.setdefault(result.scene, []).append(
                {
                    "run_id": run.id,
                    "at": run.created_at,
                    "verdict": result.verdict,
                    "exposure_ev": result.metrics.get("exposure_ev"),
                    "delta_e00_p95": delta_e.get("p95"),
                    "delta_e00_p95_excess": delta_e.get("p95_excess"),
                    "flip_mean": flip.get("mean"),
                    "flip_mean_excess": flip.get("mean_excess"),
                    "rel_rmse_max": result.metrics.get("rel_rmse_max"),
                    "job_id": result.job_id,
                    "baseline_job_id": result.baseline_job_id,
                }
            )
    return series
