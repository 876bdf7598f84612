"""Regression runs: render every scene of a suite as a job, then compare each with its baseline.

``RunService.start_run`` resolves the suite's scenes (examples, earlier jobs' stored scenes, inline documents;
film overrides; a seed derived from the run id, so two runs differ only by Monte Carlo noise), creates one
render job per scene through ``JobService`` and enqueues ``evaluate_run_task`` to run after all their merge
steps (RQ dependency, failures allowed). The evaluation compares each scene with its current baseline
(``hgcore.regression.metrics``), stores the metrics and verdicts in the run record (the history) and, when
the run failed and its schedule has a ``webhook_url``, POSTs the report with retries. A scene without a
baseline has its first render promoted to baseline version 1 (verdict pass, noted in its metrics).
"""

from __future__ import annotations

import json
import time
import uuid
from collections.abc import Callable
from typing import Any

import redis
from rq import Queue
from rq.job import Dependency

from hgcore.errors import InputError
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.queue_graph import EVALUATE_RUN_TASK, merge_rq_id
from hgcore.regression.models import RunView, SceneResult, Suite, SuiteScene
from hgcore.regression.store import RegressionStore
from hgcore.settings import SceneLimits, Settings
from hgcore.store import store_from_settings
from schemas import EXAMPLES_DIR, Scene, validate_scene
from schemas.validation import override_film
from service.jobs import JobService

EVALUATE_QUEUE = "default"


def run_seed(run_id: str) -> int:
    """The base seed of a run's renders (from its random id: independent noise per run)."""
    return int(run_id[:8], 16) & 0x7FFFFFFF


def resolve_scene(
    entry: SuiteScene,
    seed: int,
    job_scene: Callable[[str], dict[str, Any]] | None = None,
    *,
    limits: SceneLimits,
) -> Scene:
    """The scene of a suite entry with its film overrides and ``seed``, validated against ``limits`` (the
    process's settings); ``job_scene`` loads an earlier job's stored scene (service mode only)."""
    if entry.example is not None:
        path = EXAMPLES_DIR / f"{entry.example}.json"
        if not path.is_file():
            raise InputError(f"example: {entry.example!r} is not a file of schemas/examples")
        scene = json.loads(path.read_text())
    elif entry.job_id is not None:
        if job_scene is None:
            raise InputError(f"job_id: scene {entry.key!r} names a job; that needs the service")
        scene = job_scene(entry.job_id)
    else:
        assert entry.scene is not None
        scene = dict(entry.scene)
    film = {"spp": entry.spp, "width": entry.width, "height": entry.height, "seed": seed}
    return validate_scene(override_film(scene, **film), limits)


class RunService:
    """Validates suites and starts runs; used by the API and the scheduler."""

    def __init__(self, jobs: JobService, regression: RegressionStore, settings: Settings) -> None:
        self.jobs = jobs
        self.regression = regression
        self.settings = settings

    def job_scene(self, job_id: str) -> dict[str, Any]:
        """The stored scene document of an earlier job."""
        return self.jobs.scene(job_id)

    def validate_suite(self, suite: Suite) -> None:
        """Resolve every scene once (SceneError / ValueError name the problem), so that a schedule with a
        scene that cannot render is refused when it is created rather than failing at every due time."""
        for entry in suite.scenes:
            resolve_scene(entry, 0, self.job_scene, limits=self.settings)

    def start_run(
        self,
        suite: Suite,
        owner: str,
        *,
        trigger: str,
        schedule_id: str | None = None,
        due_at: float | None = None,
        webhook_url: str | None = None,
    ) -> RunView:
        """Create the run record and one render job per scene; the evaluation follows the renders."""
        run_id = uuid.uuid4().hex
        seed = run_seed(run_id)
        scenes = [
            (entry, resolve_scene(entry, seed, self.job_scene, limits=self.settings))
            for entry in suite.scenes
        ]
        results = []
        for entry, scene in scenes:
            view, _ = self.jobs.create(scene, owner, name=f"regression {entry.key} (run {run_id[:8]})")
            results.append(SceneResult(scene=entry.key, job_id=view.id))
        run = RunView(
            id=run_id,
            owner=owner,
            schedule_id=schedule_id,
            trigger=trigger,  # type: ignore[arg-type]
            due_at=due_at,
            created_at=time.time(),
            status="running",
            scenes=results,
            suite=suite,
            webhook_url=webhook_url,
        )
        self.regression.save_run(run)
        Queue(EVALUATE_QUEUE, connection=self.jobs.client).enqueue_call(
            EVALUATE_RUN_TASK,
            args=(run_id,),
            job_id=f"regression-{run_id}",
            description=f"evaluate regression run {run_id}",
            depends_on=Dependency(
                jobs=[merge_rq_id(r.job_id) for r in results if r.job_id], allow_failure=True
            ),
            timeout=self.settings.job_timeout_s,
            result_ttl=self.settings.result_ttl_s,
        )
        return run


def run_service_for(client: redis.Redis, settings: Settings) -> RunService:
    """A RunService over ``client`` and the store the settings name."""
    store = store_from_settings(settings)
    jobs = JobService(JobLifecycle(client, store), settings)
    return RunService(jobs, RegressionStore(client, store), settings)
