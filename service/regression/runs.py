"""Regression runs: render every scene of a suite as a job, then compare each with its baseline.

``RunService.start_run`` resolves the suite's scenes (examples, earlier jobs' stored scenes, inline documents;
film overrides; a seed derived from the run id, so two runs differ only by Monte Carlo noise), creates one
render job per scene through ``JobService`` and enqueues ``evaluate_run_task`` to run after all their merge
steps (RQ dependency, failures allowed). The evaluation compares each scene with its current baseline
(``service.regression.metrics``), stores the metrics and verdicts in the run record (the history) and, when
the run failed and its schedule has a ``webhook_url``, POSTs the report with retries. A scene without a
baseline has its first render promoted to baseline version 1 (verdict pass, noted in its metrics).
"""

from __future__ import annotations

import json
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import redis
from rq import Queue, get_current_job
from rq.job import Dependency

from hgcore.artifacts.keys import artifact_key
from hgcore.errors import InputError
from hgcore.jobs.queue_graph import merge_rq_id
from hgcore.jobs.status import JobStatus
from hgcore.settings import Settings
from hgcore.store import store_from_settings
from schemas import EXAMPLES_DIR, validate_scene
from service.jobs import JobService
from service.regression.images import load_render_outputs
from service.regression.metrics import compare_renders
from service.regression.models import RunView, SceneResult, Suite, SuiteScene
from service.regression.store import BASELINE_FILES, RegressionStore
from service.regression.webhooks import deliver_webhook

EVALUATE_TASK = "service.regression.runs.evaluate_run_task"
EVALUATE_QUEUE = "default"


def run_seed(run_id: str) -> int:
    """The base seed of a run's renders (from its random id: independent noise per run)."""
    return int(run_id[:8], 16) & 0x7FFFFFFF


def resolve_scene(
    entry: SuiteScene, seed: int, job_scene: Callable[[str], dict[str, Any]] | None = None
) -> dict[str, Any]:
    """The validated scene document of a suite entry with its film overrides and ``seed``; ``job_scene``
    loads an earlier job's stored scene (service mode only)."""
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
    film = dict(scene.get("film", {}))
    overrides = (("spp", entry.spp), ("width", entry.width), ("height", entry.height))
    film.update({key: value for key, value in overrides if value is not None})
    film["seed"] = seed
    return validate_scene({**scene, "film": film}).to_json_dict()


class RunService:
    """Starts and evaluates runs; used by the API, the scheduler and the queue task."""

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
            resolve_scene(entry, 0, self.job_scene)

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
        scenes = [(entry, resolve_scene(entry, seed, self.job_scene)) for entry in suite.scenes]
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
            EVALUATE_TASK,
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

    def evaluate_scene(self, run: RunView, result: SceneResult, work_dir: Path) -> SceneResult:
        """Compare one scene's finished render with the scene's current baseline."""
        assert result.job_id is not None and run.suite is not None
        job = self.jobs.get(result.job_id)
        if job is None or job.status != JobStatus.SUCCEEDED:
            state = "missing" if job is None else f"{job.status.value}: {job.error or ''}".rstrip(": ")
            return result.model_copy(
                update={
                    "verdict": "error",
                    "reasons": [f"{result.scene}: render job {result.job_id} {state}"],
                }
            )
        baseline = self.regression.current_baseline(result.scene)
        if baseline is None:
            created = self.regression.promote(result.scene, result.job_id, run.id)
            return result.model_copy(
                update={
                    "verdict": "pass",
                    "baseline_version": created.version,
                    "baseline_job_id": created.job_id,
                    "metrics": {"baseline_created": created.version},
                }
            )
        baseline_dir, current_dir = work_dir / result.scene / "baseline", work_dir / result.scene / "current"
        for name in BASELINE_FILES:
            for directory in (baseline_dir, current_dir):
                directory.mkdir(parents=True, exist_ok=True)
            (baseline_dir / name).write_bytes(
                self.regression.baseline_file(result.scene, baseline.version, name)
            )
            self.jobs.store.get_file(artifact_key(result.job_id, name), current_dir / name)
        entry = next(s for s in run.suite.scenes if s.key == result.scene)
        comparison = compare_renders(
            result.scene,
            load_render_outputs(baseline_dir),
            load_render_outputs(current_dir),
            run.suite.thresholds_for(entry),
        )
        return result.model_copy(
            update={
                "verdict": comparison.verdict,
                "reasons": comparison.reasons,
                "metrics": comparison.metrics,
                "baseline_version": baseline.version,
                "baseline_job_id": baseline.job_id,
            }
        )

    def evaluate_run(self, run_id: str) -> RunView:
        """Evaluate every scene, store the verdicts, and send the failure webhook if there is one."""
        run = self.regression.get_run(run_id)
        with tempfile.TemporaryDirectory(prefix="hgrender-regression-") as tmp:
            results = []
            for result in run.scenes:
                try:
                    results.append(self.evaluate_scene(run, result, Path(tmp)))
                except (ValueError, KeyError, OSError) as error:
                    reason = f"{result.scene}: evaluation failed: {error}"
                    results.append(result.model_copy(update={"verdict": "error", "reasons": [reason]}))
        verdicts = {r.verdict for r in results}
        status = "failed" if "fail" in verdicts else "error" if "error" in verdicts else "passed"
        run = run.model_copy(
            update={
                "scenes": results,
                "status": status,
                "finished_at": time.time(),
                "reasons": [reason for r in results for reason in r.reasons],
            }
        )
        if status != "passed" and run.webhook_url:
            outcome = deliver_webhook(
                run.webhook_url,
                {"event": f"regression.{status}", "run": run.model_dump(mode="json", exclude={"suite"})},
                retry_intervals_s=self.settings.regression_webhook_retry_intervals_s,
                timeout_s=self.settings.regression_webhook_timeout_s,
            )
            run = run.model_copy(update={"webhook": outcome})
        # One write of the final state: a finished run already carries its alert's delivery outcome.
        self.regression.save_run(run)
        return run


def run_service_for(client: redis.Redis, settings: Settings) -> RunService:
    """A RunService over ``client`` and the store the settings name."""
    store = store_from_settings(settings)
    return RunService(JobService(client, store, settings), RegressionStore(client, store), settings)


def evaluate_run_task(run_id: str) -> dict[str, Any]:
    """RQ task: evaluate a run after its renders ended (runs in a queue worker's work horse)."""
    rq_job = get_current_job()
    if rq_job is None:
        raise RuntimeError("evaluate_run_task runs inside an RQ work horse (hgrender worker)")
    run = run_service_for(rq_job.connection, Settings()).evaluate_run(run_id)
    return {"run_id": run.id, "status": run.status}
