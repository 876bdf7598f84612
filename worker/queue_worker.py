"""The RQ worker that runs render chunks: queue order, heartbeats, and detection of dead workers' chunks.

RQ forks a work horse per job (a native crash or SIGKILL of the horse fails only that attempt; the
worker then retries the chunk per its ``Retry``). A chunk whose whole worker died stays in the queue's
StartedJobRegistry until its heartbeat lapses; any live worker's maintenance pass then retries it
(``StartedJobRegistry.cleanup`` → ``job.retry``). Two knobs decide how soon: the heartbeat TTL, which
RQ fixes at monitoring interval + 60 s and this worker makes ``worker_heartbeat_grace_s``, and the
idle wake-up between maintenance passes, which RQ ties to ``worker_ttl - 15`` and this worker caps at
``worker_maintenance_interval_s``. The queue tasks themselves live in ``worker.tasks`` (referenced by
name, so this module never imports the renderer).

Graceful shutdown (SIGTERM, as Kubernetes and ``docker stop`` send it): RQ's warm shutdown already takes
no new chunk and waits for the running one. This worker bounds that wait by ``worker_shutdown_grace_s``:
at the first heartbeat tick after the grace ran out (so within grace + ``worker_monitoring_interval_s``)
it kills its work horse and puts the chunk back at the front of its queue, without spending one of the
chunk's retries. A second SIGTERM (cold shutdown) hands the chunk back at once. A chunk is handed back only
while RQ still records it as started, so a chunk that completed is never queued again; a re-run
overwrites the same artifact key, so a job ends with one set of artifacts either way.

A job's final step (its merge, or the only step of a one-chunk job) fails the job itself when it raises on
its last attempt. When it cannot, because its horse died (killed, out of memory) or its whole worker did
on that attempt, this worker fails the job: in ``handle_job_failure`` for a dead horse, and in an
exception handler for the abandoned step that a maintenance pass finds. A failed chunk of a multi-chunk job
needs neither: the merge step, which runs after failed chunks too, reports it.
"""

from __future__ import annotations

import logging
import socket
import uuid
from types import FrameType
from typing import Any

import redis
from rq import Queue, Worker
from rq.exceptions import AbandonedJobError
from rq.executions import Execution
from rq.job import Job, JobStatus
from rq.registry import StartedJobRegistry
from rq.utils import now

from hgcore.jobs.queue_graph import FINAL_STEP_TASKS
from hgcore.jobs.records import JobRecords
from hgcore.redis_clients import redis_client
from hgcore.settings import QUEUE_NAMES, Settings
from hgcore.store import store_from_settings


class RenderWorker(Worker):
    """An RQ ``Worker`` with a configurable heartbeat grace and maintenance wake-up, whose warm shutdown
    hands its chunk back to the queue after ``worker_shutdown_grace_s``, and which fails the job of a final
    step that died (both from ``settings``)."""

    _handing_back_job_id: str | None = None

    def __init__(
        self, queues: list[Queue], *args: Any, settings: Settings | None = None, **options: Any
    ) -> None:
        super().__init__(queues, *args, **options)
        # RQ rebuilds workers from their Redis key with its own arguments only (``Worker.all``, ``rq info``):
        # those read the settings from the environment.
        self.settings = settings if settings is not None else Settings()
        self.push_exc_handler(self.handle_abandoned_final_step)

    def get_heartbeat_ttl(self, job: Job, working_time: float = 0.0) -> int:
        monitoring_s = self.job_monitoring_interval
        if job.timeout and job.timeout > 0:
            monitoring_s = int(min(job.timeout - working_time, monitoring_s))
        return int(monitoring_s) + self.settings.worker_heartbeat_grace_s

    @property
    def dequeue_timeout(self) -> int:
        return max(1, min(self.worker_ttl - 15, self.maintenance_interval))

    def maintain_heartbeats(self, job: Job, execution: Execution) -> None:
        """RQ's heartbeat tick while the work horse runs; after a warm-shutdown request whose grace ran
        out, also stop the horse (``handle_job_failure`` below then hands the chunk back)."""
        super().maintain_heartbeats(job, execution)
        # RQ records the warm-shutdown request in these two attributes (request_stop / _shutdown).
        if not self._stop_requested or self._shutdown_requested_date is None:
            return
        waited_s = (now() - self._shutdown_requested_date).total_seconds()
        if waited_s >= self.settings.worker_shutdown_grace_s and self._handing_back_job_id is None:
            self.log.warning(
                "Worker %s: job %s still running %.0f s after SIGTERM; handing it back to the queue",
                self.name,
                job.id,
                waited_s,
            )
            self._handing_back_job_id = job.id
            self.kill_horse()

    def handle_job_failure(
        self,
        job: Job,
        queue: Queue,
        started_job_registry: StartedJobRegistry | None = None,
        exc_string: str = "",
        execution: Execution | None = None,
    ) -> None:
        """A horse this worker stopped for shutdown is no failure: requeue its job instead."""
        if job.id == self._handing_back_job_id:
            self._handing_back_job_id = None
            self.hand_back(job, queue, execution)
            return
        super().handle_job_failure(job, queue, started_job_registry, exc_string, execution)
        if job.get_status(refresh=True) == JobStatus.FAILED:  # neither retried nor stopped by a cancel
            last_lines = exc_string.strip().splitlines()[-1:]
            self.fail_job_of_final_step(job, last_lines[0] if last_lines else "failed")

    def handle_abandoned_final_step(self, job: Job, exc_type: type, *_exc_info: object) -> None:
        """Exception handler (also called for abandoned jobs by the registries' cleanup): a final step
        whose worker died on its last attempt fails its job. Returns None: the next handlers still run."""
        if exc_type is AbandonedJobError and not job.retries_left:
            self.fail_job_of_final_step(job, "its worker died (heartbeat lapsed) on the last attempt")

    def fail_job_of_final_step(self, job: Job, reason: str) -> None:
        """Fail the hgrender job whose final step ``job`` failed for good with ``reason`` (one line),
        unless the step already did, or the job ended otherwise."""
        if job.func_name not in FINAL_STEP_TASKS:
            return
        from worker.tasks import fail_job  # the worker process has it loaded (preload_renderer)

        jobs = JobRecords(self.connection, store_from_settings(self.settings), self.settings)
        fail_job(jobs, job.args[0], f"{job.description}: {reason}")

    def request_force_stop(self, signum: int, frame: FrameType | None) -> None:
        """Cold shutdown (second SIGTERM/SIGINT): RQ kills the horse and exits; hand its job back first."""
        job, execution = self.get_current_job(), self.execution
        try:
            super().request_force_stop(signum, frame)
        except SystemExit:
            if job is not None:
                self.hand_back(job, Queue(job.origin, connection=self.connection), execution)
            raise

    def hand_back(self, job: Job, queue: Queue, execution: Execution | None) -> None:
        """Put a job whose horse is dead back at the front of ``queue``, retries untouched.

        Only a job still marked started is requeued: one that finished (or failed) before its horse
        died must not run again. It is enqueued before its execution leaves the StartedJobRegistry, so a
        crash in between leaves it queued (the registry's cleanup ignores jobs no longer started)."""
        if job.get_status(refresh=True) != JobStatus.STARTED:
            return
        queue.enqueue_job(job, at_front=True)
        with self.connection.pipeline() as pipeline:
            self.cleanup_execution(job, pipeline=pipeline, execution=execution)
            pipeline.execute()
        self.log.info("Worker %s: handed job %s back to queue %s", self.name, job.id, queue.name)


def worker_name() -> str:
    """Host name plus a short random suffix (several workers per host)."""
    return f"{socket.gethostname()}-{uuid.uuid4().hex[:6]}"


def build_worker(settings: Settings, client: redis.Redis, name: str | None = None) -> RenderWorker:
    queues = [Queue(queue_name, connection=client) for queue_name in QUEUE_NAMES]
    worker = RenderWorker(
        queues,
        name=name or worker_name(),
        connection=client,
        maintenance_interval=settings.worker_maintenance_interval_s,
        worker_ttl=settings.worker_ttl_s,
        job_monitoring_interval=settings.worker_monitoring_interval_s,
        default_result_ttl=settings.result_ttl_s,
        settings=settings,
    )
    return worker


def run_worker(settings: Settings, *, burst: bool = False, name: str | None = None) -> int:
    """Work the ``high``, ``default`` and ``low`` queues (in that order) until stopped; exit code 0."""
    if not settings.redis_url:
        raise ValueError("redis_url: REDIS_URL must name the Redis server the API uses")
    client = redis_client(settings.redis_url)
    worker = build_worker(settings, client, name)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # The worker that holds RQ's scheduler lock also moves retries whose backoff has elapsed back to queues.
    worker.work(burst=burst, with_scheduler=True, logging_level="INFO")
    return 0
