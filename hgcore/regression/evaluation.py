"""Evaluation of a regression run once its renders ended: each scene's render is compared with the scene's
current baseline (``hgcore.regression.metrics``); the metrics and verdicts are stored in the run record (the
history) and, when the run failed and its schedule has a ``webhook_url``, the report is POSTed with retries.
A scene without a baseline has its first render promoted to baseline version 1 (verdict pass, noted in its
metrics).

It runs in a queue worker's work horse (``worker.tasks.evaluate_run_task``, enqueued by
``service.regression.runs`` after the run's merge steps), so it needs only the job domain: a render job's
view and artifacts come from its ``JobLifecycle``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from hgcore.artifacts.keys import artifact_key
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.status import JobStatus
from hgcore.regression.images import load_render_outputs
from hgcore.regression.metrics import compare_renders
from hgcore.regression.models import RunView, SceneResult
from hgcore.regression.store import BASELINE_FILES, RegressionStore
from hgcore.regression.webhooks import deliver_webhook
from hgcore.settings import Settings


class RunEvaluator:
    """Compares a run's renders with their baselines and records the verdicts."""

    def __init__(self, jobs: JobLifecycle, regression: RegressionStore, settings: Settings) -> None:
        self.jobs = jobs
        self.regression = regression
        self.settings = settings

    @classmethod
    def of(cls, jobs: JobLifecycle, settings: Settings) -> RunEvaluator:
        """An evaluator over the jobs' Redis and artifact store."""
        return cls(jobs, RegressionStore(jobs.client, jobs.store), settings)

    def evaluate_scene(self, run: RunView, result: SceneResult, work_dir: Path) -> SceneResult:
        """Compare one scene's finished render with the scene's current baseline."""
        assert result.job_id is not None and run.suite is not None
        job = self.jobs.view(result.job_id)
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
