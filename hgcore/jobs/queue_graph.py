"""The RQ job graph of a render job, and the one place that names its tasks, RQ ids and queues.

A job of ``K > 1`` chunks becomes ``K`` RQ chunk jobs (``<id>-chunk-<i>``; the worker renders spp
partition ``i`` of ``worker.render.chunks.plan_chunks(spp, K, seed)``, each with its own seed) on the queue
its priority names, plus one merge job (``<id>-merge``) that depends on all chunks (failures allowed, so the
merge step is also where a failed chunk fails the job). A job of one chunk becomes a single RQ job under the
merge job's id that renders and merges in one work horse: no partial upload, and one dequeue and fork
instead of two (half the queue's latency for small jobs). Either way ``<id>-merge`` is the job's final step,
the one regression evaluations depend on. Tasks are named by their dotted path, so the API enqueues them
without importing the worker.
"""

from __future__ import annotations

from typing import Any

import redis
from rq import Queue, Retry
from rq.exceptions import NoSuchJobError
from rq.job import Dependency
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from hgcore.settings import Settings

PRIORITY_QUEUES: dict[str, str] = {"high": "high", "normal": "default", "low": "low"}
"""Job priority → RQ queue (workers dequeue ``hgcore.settings.QUEUE_NAMES`` in order)."""
CHUNK_TASK = "worker.tasks.render_chunk_task"
MERGE_TASK = "worker.tasks.merge_task"
RENDER_JOB_TASK = "worker.tasks.render_job_task"
EVALUATE_RUN_TASK = "worker.tasks.evaluate_run_task"
"""Evaluates a regression run after its renders (``hgcore.regression.evaluation``)."""
TASKS = (CHUNK_TASK, MERGE_TASK, RENDER_JOB_TASK, EVALUATE_RUN_TASK)
"""Every task a worker runs (``tests/test_layering.py`` imports them with ``service`` absent)."""
FINAL_STEP_TASKS = frozenset({MERGE_TASK, RENDER_JOB_TASK})
"""Tasks that end a job: when one fails for good, the job fails (``JobLifecycle.fail``)."""


def chunk_rq_id(job_id: str, index: int) -> str:
    return f"{job_id}-chunk-{index}"


def merge_rq_id(job_id: str) -> str:
    """RQ id of the job's final step: its merge, or its only step when it has one chunk."""
    return f"{job_id}-merge"


def rq_ids(job_id: str, chunk_count: int) -> list[str]:
    """Every RQ id of a job of ``chunk_count`` chunks, its final step last."""
    chunk_ids = [chunk_rq_id(job_id, i) for i in range(chunk_count)] if chunk_count > 1 else []
    return [*chunk_ids, merge_rq_id(job_id)]


def enqueue_job_graph(
    pipe: redis.client.Pipeline,
    queue: Queue,
    job_id: str,
    chunk_count: int,
    settings: Settings,
    only: str | None = None,
) -> None:
    """Add, in ``pipe``'s transaction, the chunk jobs (queued) and the merge job (deferred on all chunks,
    failures allowed), or for a one-chunk job the single job that renders and merges. ``only``: recreate
    just that RQ job (reconciliation), at the front of the queue.

    Finished work first: a retry goes to the front of its queue, and so does a merge once its last chunk
    ended, so a backlog of new chunks delays neither (jobs finish in submission order)."""
    retry = (
        Retry(
            max=settings.chunk_retry_max,
            interval=settings.chunk_retry_intervals_s,
            enqueue_at_front=True,
        )
        if settings.chunk_retry_max > 0
        else None
    )
    common: dict[str, Any] = {
        "timeout": settings.job_timeout_s,
        "result_ttl": settings.result_ttl_s,
        "failure_ttl": settings.result_ttl_s,
        "retry": retry,
    }
    if chunk_count == 1:
        steps = [(RENDER_JOB_TASK, (job_id,), merge_rq_id(job_id), f"render and merge job {job_id}")]
    else:
        steps = [
            (CHUNK_TASK, (job_id, index), chunk_rq_id(job_id, index), f"render chunk {index} of job {job_id}")
            for index in range(chunk_count)
        ]
    for task, args, rq_id, description in steps:
        if only not in (None, rq_id):
            continue
        step = queue.create_job(task, args=args, job_id=rq_id, description=description, **common)
        # Enqueued at the back now; any later enqueue (a retry, a dead worker's chunk found by the
        # maintenance pass) goes to the front (RQ's ``Job.should_enqueue_at_front``).
        step.enqueue_at_front = True
        queue.enqueue_job(step, pipeline=pipe, at_front=only is not None)
    if chunk_count == 1 or only not in (None, merge_rq_id(job_id)):
        return
    chunk_ids = [rq_id for _, _, rq_id, _ in steps]
    merge = queue.create_job(
        MERGE_TASK,
        args=(job_id,),
        job_id=merge_rq_id(job_id),
        description=f"merge job {job_id}",
        depends_on=Dependency(jobs=chunk_ids, allow_failure=True, enqueue_at_front=True),
        status=RQJobStatus.DEFERRED,
        **common,
    )
    merge.origin = queue.name
    merge.save(pipeline=pipe)
    merge.register_dependency(pipeline=pipe)
    pipe.sadd(queue.redis_queues_keys, queue.key)


def chunk_failures(client: redis.Redis, job_id: str, chunk_count: int) -> list[str]:
    """One line per chunk of a multi-chunk job that did not finish: its index and last error (what the
    merge step fails the job with)."""
    failures = []
    for index in range(chunk_count):
        try:
            rq_job = RQJob.fetch(chunk_rq_id(job_id, index), connection=client)
        except NoSuchJobError:
            failures.append(f"chunk {index}: lost from the queue")
            continue
        if rq_job.get_status() != RQJobStatus.FINISHED:
            result = rq_job.latest_result()
            reason = (result.exc_string or "").strip().splitlines()[-1:] if result else []
            failures.append(f"chunk {index}: {reason[0] if reason else rq_job.get_status()}")
    return failures
