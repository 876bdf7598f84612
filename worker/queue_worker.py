"""The RQ worker that runs render chunks: queue order, heartbeats, and detection of dead workers' chunks.

RQ forks a work horse per job (a native crash or SIGKILL of the horse fails only that attempt; the
worker then retries the chunk per its ``Retry``, at the front of its queue). A horse dies with its worker
(``PR_SET_PDEATHSIG``) instead of rendering on as an orphan, and the worker removes the temporary folders
of any horse that was killed. A chunk whose whole worker died stays in the queue's
StartedJobRegistry until its heartbeat lapses; any live worker's maintenance pass then retries it
(``StartedJobRegistry.cleanup`` → ``job.retry``). Two knobs decide how soon: the heartbeat TTL, which
RQ fixes at monitoring interval + 60 s and this worker makes ``worker_heartbeat_grace_s``, and the
idle wake-up between maintenance passes, which RQ ties to ``worker_ttl - 15`` and this worker caps at
``worker_maintenance_interval_s``. The queue tasks themselves live in ``worker.tasks`` (referenced by
name, so this module never imports the renderer nor the tasks); what both need (the settings the worker
binds for its horses, the horses' temporary folders) lives in ``worker.horse``.

Graceful shutdown (SIGTERM, as Kubernetes and ``docker stop`` send it): RQ's warm shutdown already takes
no new chunk and waits for the running one. This worker bounds that wait by ``worker_shutdown_grace_s``:
at the first heartbeat tick after the grace ran out (so within grace + ``worker_monitoring_interval_s``)
it kills its work horse and puts the chunk back at the front of its queue, without spending one of the
chunk's retries. A second SIGTERM (cold shutdown) hands the chunk back at once. A chunk is handed back only
while RQ still records it as started, so a chunk that completed is never queued again; a re-run
overwrites the same artifact key, so a job ends with one set of artifacts either way.

A job's final step (its merge, or the only step of a one-chunk job) fails the job itself when it raises on
its last attempt. When it cannot, because its horse died (killed, out of memory) or its whole worker did
on that attempt, this worker fails the job (``JobLifecycle.fail``): in ``handle_job_failure`` for a dead
horse, and in an exception handler for the abandoned step that a maintenance pass finds. A failed chunk of
a multi-chunk job needs neither: the merge step, which runs after failed chunks too, reports it.

Redis outages (a restart of the private Redis, a failover): the worker's client retries every command for
up to ``worker_redis_outage_s`` (bounded back-off), so a horse keeps rendering and the worker keeps its
chunk across a short outage. A longer one ends ``Worker.work``; ``run_worker`` then stops the horse, waits
for Redis (bounded back-off, never a crash loop), hands the chunk back and works on as a fresh worker.

RQ's scheduler (it moves retries whose back-off elapsed back to their queue) runs as a child process of
whichever worker holds its lock. Here that child dies with its worker (``PR_SET_PDEATHSIG``: SIGTERM,
so it releases its locks), and a lock whose holder stopped refreshing it for ``SCHEDULER_LOCK_STALE_S``
(its process was SIGKILLed with its worker) is freed by the next maintenance pass instead of blocking
retries for RQ's 61 s lock lifetime.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import math
import os
import signal
import socket
import threading
import time
import uuid
from types import FrameType
from typing import Any

import redis
from redis.backoff import ExponentialBackoff
from redis.retry import Retry
from rq import Queue, Worker
from rq.exceptions import AbandonedJobError, InvalidJobOperation, NoSuchJobError
from rq.executions import Execution
from rq.job import Job, JobStatus
from rq.registry import StartedJobRegistry
from rq.scheduler import RQScheduler
from rq.scripts import release_lock
from rq.utils import now

from hgcore.errors import InputError
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.queue_graph import FINAL_STEP_TASKS
from hgcore.jobs.reconcile import QueueReconciler
from hgcore.redis_clients import redis_client
from hgcore.settings import QUEUE_NAMES, Settings
from hgcore.store import store_from_settings
from worker.horse import bind_settings, remove_dead_horse_temp_dirs, remove_horse_temp_dirs

SCHEDULER_LOCK_STALE_S = 10.0
"""A scheduler lock not refreshed for this long belongs to a dead scheduler (a live one refreshes it every
second, RQ's scheduler interval), and is freed for another worker's scheduler."""
MAINTENANCE_LOCK_TTL_S = 30
"""Lifetime of a queue's registry-cleaning lock. RQ gives it 899 s: a worker killed while it cleaned (OOM,
node loss, SIGKILL) left the lock behind and no worker detected abandoned chunks on that queue for 15
minutes. Cleaning takes milliseconds; 30 s bounds that blind spot and still never lets two workers clean
at once."""
RECONCILE_DUE_KEY = "hgrender:reconcile-due"
"""Exists (with a TTL of ``reconcile_interval_s``) while the last periodic reconciliation is recent."""
SCHEDULER_STOP_DEADLINE_S = 5.0
"""Longest a scheduler child takes to stop once asked (it exits then, its locks left to lapse)."""
_PR_SET_PDEATHSIG = 1
_REDIS_BACKOFF_CAP_S = 1.0

log = logging.getLogger(__name__)


class MaintenanceAtDebug(logging.Filter):
    """RQ logs its registry maintenance at INFO: four lines per ``worker_maintenance_interval_s`` (5 s by
    default) and worker, over half of a ``serve.log``. This filter (on RQ's worker logger) re-levels them to
    DEBUG, so they appear only where DEBUG is on; every other record passes unchanged."""

    MESSAGES = frozenset(
        {"Worker %s: cleaning registries for queue: %s", "Worker %s: cleaning group registries"}
    )

    def filter(self, record: logging.LogRecord) -> bool:
        if record.msg not in self.MESSAGES:
            return True
        record.levelno, record.levelname = logging.DEBUG, logging.getLevelName(logging.DEBUG)
        return logging.getLogger(record.name).isEnabledFor(logging.DEBUG)


def quiet_rq_maintenance() -> None:
    """Install ``MaintenanceAtDebug`` on RQ's worker logger (once per process)."""
    rq_log = logging.getLogger("rq.worker")
    if not any(isinstance(f, MaintenanceAtDebug) for f in rq_log.filters):
        rq_log.addFilter(MaintenanceAtDebug())


def die_with_parent(signum: signal.Signals, parent_pid: int) -> bool:
    """Ask Linux to send ``signum`` to this process when its parent dies (``PR_SET_PDEATHSIG``); False
    when the parent (``parent_pid``, read before the fork) is already gone."""
    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signum)
    return os.getppid() == parent_pid


class RenderScheduler(RQScheduler):
    """RQ's scheduler, as a child process that ends (gracefully: SIGTERM, releasing its locks) when the
    worker that forked it dies, instead of living on orphaned with the locks."""

    worker_pid = 0

    def start(self) -> Any:
        self.worker_pid = os.getpid()
        return super().start()

    def work(self) -> None:
        if die_with_parent(signal.SIGTERM, self.worker_pid):
            super().work()

    def request_stop(self, signum: int | None = None, frame: FrameType | None = None) -> None:
        """RQ's graceful stop (release the locks at the next loop), with a deadline: with Redis gone the
        release would retry for the client's whole outage window, long after the worker and `serve` have
        ended. The locks lapse by their TTL, and the next scheduler frees them
        (``free_stale_scheduler_locks``)."""
        super().request_stop(signum, frame)
        deadline = threading.Timer(SCHEDULER_STOP_DEADLINE_S, os._exit, args=(0,))
        deadline.daemon = True
        deadline.start()


class RenderQueue(Queue):
    """RQ's queue with a registry-cleaning lock of ``MAINTENANCE_LOCK_TTL_S`` instead of 899 s."""

    def acquire_maintenance_lock(self) -> bool:
        return bool(self.connection.set(self.registry_cleaning_key, 1, nx=True, ex=MAINTENANCE_LOCK_TTL_S))


class RenderWorker(Worker):
    """An RQ ``Worker`` with a configurable heartbeat grace and maintenance wake-up, whose warm shutdown
    hands its chunk back to the queue after ``worker_shutdown_grace_s``, and which fails the job of a final
    step that died (all from ``settings``). Its horses and scheduler die with it; its maintenance pass also
    frees dead schedulers' locks, removes killed horses' temporary folders and, once per
    ``reconcile_interval_s`` across workers, re-enqueues stranded steps."""

    _handing_back_job_id: str | None = None
    _last_horse_pid: int = 0
    _worker_pid: int = 0
    executing: tuple[Job, Queue] | None = None
    """The chunk being executed and its queue; still set when ``execute_job`` ended with an exception
    (Redis lost mid-chunk), so that ``recover_after_outage`` can hand it back."""

    def __init__(
        self, queues: list[Queue], *args: Any, settings: Settings | None = None, **options: Any
    ) -> None:
        super().__init__(queues, *args, **options)
        # RQ rebuilds workers from their Redis key with its own arguments only (``Worker.all``, ``rq info``):
        # those read the settings from the environment.
        self.settings = settings if settings is not None else Settings()
        self.push_exc_handler(self.handle_abandoned_final_step)

    def _start_scheduler(
        self,
        burst: bool = False,
        logging_level: str | None = "INFO",
        date_format: str = "",
        log_format: str = "",
    ) -> None:
        """RQ's own start, with a ``RenderScheduler`` instead of its ``RQScheduler``."""
        self.scheduler = RenderScheduler(
            self.queues,
            connection=self.connection,
            logging_level=logging_level if logging_level is not None else self.log.level,
            serializer=self.serializer,
        )
        self.scheduler.acquire_locks()
        if self.scheduler.acquired_locks:
            if burst:
                try:
                    self.scheduler.register_birth()
                    self.scheduler.enqueue_scheduled_jobs()
                finally:
                    self.scheduler.release_locks()
                    self.scheduler.register_death()
            else:
                self.scheduler.start()

    def run_maintenance_tasks(self) -> None:
        """RQ's maintenance (restart a dead scheduler child, clean registries: abandoned chunks are retried
        here), after freeing scheduler locks whose holder died."""
        self.free_stale_scheduler_locks()
        remove_dead_horse_temp_dirs()
        self.reconcile_if_due()
        super().run_maintenance_tasks()

    def reconcile_if_due(self) -> dict[str, str]:
        """Once per ``reconcile_interval_s`` across all workers (a Redis key decides which), re-enqueue the
        stranded steps of unfinished jobs (``hgcore.jobs.reconcile``): a worker killed between two of RQ's
        steps (a merge marked queued but pushed to no queue, say) must not leave a job unfinished."""
        interval_s = self.settings.reconcile_interval_s
        if not self.connection.set(RECONCILE_DUE_KEY, self.name, nx=True, ex=interval_s):
            return {}
        lifecycle = JobLifecycle(self.connection, store_from_settings(self.settings))
        revived = QueueReconciler(lifecycle, self.settings).reconcile()
        for rq_id, reason in revived.items():
            self.log.warning("Worker %s: re-enqueued stranded %s (%s)", self.name, rq_id, reason)
        return revived

    def free_stale_scheduler_locks(self) -> list[str]:
        """Delete each queue's scheduler lock that went unrefreshed for ``SCHEDULER_LOCK_STALE_S``; return
        the queue names. RQ sets a lock to live ``interval + 60`` s and its holder refreshes it every
        ``interval``, so the remaining lifetime tells how long ago the holder was last alive."""
        freed = []
        for queue in self.queues:
            key = RQScheduler.get_locking_key(queue.name)
            holder, ttl_ms = self.connection.get(key), self.connection.pttl(key)
            lifetime_ms = (1 + 60) * 1000  # RQScheduler's default interval (1 s) + 60
            if holder is None or ttl_ms < 0 or lifetime_ms - ttl_ms < SCHEDULER_LOCK_STALE_S * 1000:
                continue
            if release_lock(self.connection, key, holder.decode()):
                self.log.warning(
                    "Worker %s: freed the scheduler lock of queue %s (holder %s silent for %.0f s)",
                    self.name,
                    queue.name,
                    holder.decode(),
                    (lifetime_ms - ttl_ms) / 1000,
                )
                freed.append(queue.name)
        return freed

    def execute_job(self, job: Job, queue: Queue) -> None:
        self.executing = (job, queue)
        super().execute_job(job, queue)
        self.executing = None

    def fork_work_horse(self, job: Job, queue: Queue) -> None:
        """RQ's fork; then the parent also puts the horse in a process group of its own. RQ's horse calls
        ``setpgrp`` itself, but a stop (a cancel) that comes before it has run would make ``kill_horse``'s
        ``killpg(getpgid(horse))`` kill the worker's own group — the worker with it, and every job queued
        after it waits for a worker that is gone (seen in CI). Both sides calling it is the usual fix."""
        self._worker_pid = os.getpid()
        super().fork_work_horse(job, queue)
        with contextlib.suppress(ProcessLookupError, PermissionError):  # gone, or already its own leader
            os.setpgid(self.horse_pid, self.horse_pid)
        self._last_horse_pid = self.horse_pid

    def main_work_horse(self, job: Job, queue: Queue) -> None:
        """The forked horse: it dies with its worker (SIGKILL; the chunk is then retried once the
        worker's heartbeat lapsed), rather than render on unsupervised as an orphan."""
        if not die_with_parent(signal.SIGKILL, self._worker_pid):
            os._exit(1)
        super().main_work_horse(job, queue)

    def monitor_work_horse(self, job: Job, queue: Queue, execution: Execution) -> None:
        """RQ's monitoring; then whatever a killed horse left in its temporary folders is removed."""
        try:
            super().monitor_work_horse(job, queue, execution)
        finally:
            remove_horse_temp_dirs(self._last_horse_pid)

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
        # RQ keeps a busy worker's own key alive for monitoring interval + 60 s; a worker SIGKILLed mid-chunk
        # then counted as alive (/readyz, metrics) and blocked its name — a worker restarted under the same
        # name refuses to start while the key exists — for a minute. Let it lapse with the chunk's heartbeat.
        self.connection.expire(self.key, self.get_heartbeat_ttl(job))
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
        lifecycle = JobLifecycle(self.connection, store_from_settings(self.settings))
        lifecycle.fail(job.args[0], f"{job.description}: {reason}")

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
        try:
            status = job.get_status(refresh=True)
        except (InvalidJobOperation, NoSuchJobError):
            # Deleted meanwhile (a canceled job its owner removed; RQ then fails to enqueue its dependents
            # and quits its loop): there is nothing to hand back, and raising here killed the worker.
            return
        if status != JobStatus.STARTED:
            return
        queue.enqueue_job(job, at_front=True)
        with self.connection.pipeline() as pipeline:
            self.cleanup_execution(job, pipeline=pipeline, execution=execution)
            pipeline.execute()
        self.log.info("Worker %s: handed job %s back to queue %s", self.name, job.id, queue.name)


def worker_name() -> str:
    """Host name plus a short random suffix (several workers per host)."""
    return f"{socket.gethostname()}-{uuid.uuid4().hex[:6]}"


def worker_redis_client(settings: Settings) -> redis.Redis:
    """The worker's Redis client: every command is retried, with back-off capped at 1 s, for up to
    ``worker_redis_outage_s`` (the client is inherited by work horses and the scheduler child)."""
    if not settings.redis_url:
        raise InputError("redis_url: REDIS_URL must name the Redis server the API uses")
    retries = math.ceil(settings.worker_redis_outage_s / _REDIS_BACKOFF_CAP_S)
    retry = Retry(ExponentialBackoff(cap=_REDIS_BACKOFF_CAP_S, base=0.05), retries)
    return redis_client(settings.redis_url, retry=retry, socket_connect_timeout=2.0)


def wait_for_redis(client: redis.Redis, max_backoff_s: float = 5.0) -> None:
    """Block until ``client``'s server answers PING, retrying with back-off (0.5 s doubling up to
    ``max_backoff_s``), logging each failure: a worker started before Redis, or outliving it, waits."""
    backoff_s = 0.5
    while True:
        try:
            client.ping()
            return
        except (redis.exceptions.ConnectionError, redis.exceptions.TimeoutError) as error:
            log.warning("Redis unavailable (%s); retrying in %.1f s", error, backoff_s)
        time.sleep(backoff_s)
        backoff_s = min(max_backoff_s, 2 * backoff_s)


def build_worker(settings: Settings, client: redis.Redis, name: str | None = None) -> RenderWorker:
    """A worker of the ``high``, ``default`` and ``low`` queues whose horses run with ``settings``."""
    bind_settings(settings)
    queues = [RenderQueue(queue_name, connection=client) for queue_name in QUEUE_NAMES]
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
    """Work the ``high``, ``default`` and ``low`` queues (in that order) until stopped; exit code 0.

    Waits for Redis first, and again whenever an outage outlasted the client's retries; then a fresh
    worker (same name) takes over, after the previous one's horse was stopped and its chunk handed back.
    """
    client = worker_redis_client(settings)
    # Without retries: a PING that fails fast, so waiting logs each attempt.
    probe = redis_client(
        str(settings.redis_url), retry=Retry(ExponentialBackoff(), 0), socket_connect_timeout=1.0
    )
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    quiet_rq_maintenance()
    while True:
        wait_for_redis(probe)
        worker = build_worker(settings, client, name)
        try:
            # The worker that holds RQ's scheduler lock also moves retries whose backoff elapsed to queues.
            worker.work(burst=burst, with_scheduler=True, logging_level="INFO")
        except (redis.exceptions.ConnectionError, redis.exceptions.TimeoutError) as error:
            log.warning("Worker %s: lost Redis (%s); waiting for it", worker.name, error)
        # RQ records a stop request (SIGTERM/SIGINT, idle or busy) by its date.
        if burst or worker._stop_requested or worker._shutdown_requested_date is not None:
            return 0
        recover_after_outage(worker, probe)


def recover_after_outage(worker: RenderWorker, probe: redis.Redis) -> None:
    """After ``worker.work`` ended without a stop request (Redis was gone for longer than the client
    retries, or RQ quit on an unhandled exception, e.g. a job deleted while its stop was handled): stop
    its horse and scheduler, wait for Redis, hand the chunk it held back to its queue and record the
    worker's death, so a fresh worker of the same name can register."""
    executing, execution = worker.executing, worker.execution
    if worker.horse_pid:
        worker.kill_horse()
        with contextlib.suppress(ChildProcessError):
            os.waitpid(worker.horse_pid, 0)
    if worker.scheduler is not None and worker.scheduler._process is not None:
        worker.scheduler._process.terminate()
        worker.scheduler._process.join(timeout=10)
    wait_for_redis(probe)
    with contextlib.suppress(redis.exceptions.RedisError):
        if executing is not None:
            worker.hand_back(*executing, execution)
        worker.register_death()
