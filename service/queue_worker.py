"""The RQ worker that runs render chunks: queue order, heartbeats, and detection of dead workers' chunks.

RQ forks a work horse per job (a native crash or SIGKILL of the horse fails only that attempt; the
worker then retries the chunk per its ``Retry``). A chunk whose whole worker died stays in the queue's
StartedJobRegistry until its heartbeat lapses; any live worker's maintenance pass then retries it
(``StartedJobRegistry.cleanup`` → ``job.retry``). Two knobs decide how soon: the heartbeat TTL, which
RQ fixes at monitoring interval + 60 s and this worker makes ``worker_heartbeat_grace_s``, and the
idle wake-up between maintenance passes, which RQ ties to ``worker_ttl - 15`` and this worker caps at
``worker_maintenance_interval_s``. The queue tasks themselves live in ``worker.tasks`` (referenced by
name, so this module never imports the renderer).
"""

from __future__ import annotations

import logging
import socket
import uuid

import redis
from rq import Queue, Worker
from rq.job import Job

from service.core.config import QUEUE_NAMES, Settings


class RenderWorker(Worker):
    """An RQ ``Worker`` with a configurable heartbeat grace and maintenance wake-up."""

    heartbeat_grace_s: int = 60

    def get_heartbeat_ttl(self, job: Job, working_time: float = 0.0) -> int:
        monitoring_s = self.job_monitoring_interval
        if job.timeout and job.timeout > 0:
            monitoring_s = int(min(job.timeout - working_time, monitoring_s))
        return int(monitoring_s) + self.heartbeat_grace_s

    @property
    def dequeue_timeout(self) -> int:
        return max(1, min(self.worker_ttl - 15, self.maintenance_interval))


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
    )
    worker.heartbeat_grace_s = settings.worker_heartbeat_grace_s
    return worker


def run_worker(settings: Settings, *, burst: bool = False, name: str | None = None) -> int:
    """Work the ``high``, ``default`` and ``low`` queues (in that order) until stopped; exit code 0."""
    if not settings.redis_url:
        raise ValueError("redis_url: REDIS_URL must name the Redis server the API uses")
    client = redis.Redis.from_url(settings.redis_url)
    worker = build_worker(settings, client, name)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # The worker that holds RQ's scheduler lock also moves retries whose backoff has elapsed back to queues.
    worker.work(burst=burst, with_scheduler=True, logging_level="INFO")
    return 0
