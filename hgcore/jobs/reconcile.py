"""Reconciliation: finds the RQ steps of unfinished jobs that nothing will ever run, and revives them.

A crash between two of RQ's non-atomic steps (a worker SIGKILLed while it moves a job between a queue and a
registry), or a Redis restarted from a slightly older AOF, can leave a chunk or merge marked queued in no
queue, or lose it. ``hgrender serve`` reconciles at start and after each Redis restart, and one worker per
``reconcile_interval_s`` does so periodically (``worker.queue_worker``); both use this class, which reads
the jobs through their ``JobLifecycle`` (no API).
"""

from __future__ import annotations

import time

import redis
from rq import Queue
from rq.exceptions import NoSuchJobError
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from hgcore.jobs.keys import RECONCILE_LOCK
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.queue_graph import PRIORITY_QUEUES, enqueue_job_graph, merge_rq_id, rq_ids
from hgcore.settings import Settings

_RQ_ENDED = frozenset({RQJobStatus.FINISHED, RQJobStatus.FAILED, RQJobStatus.STOPPED, RQJobStatus.CANCELED})


class QueueReconciler:
    """Compares the unfinished jobs' RQ steps with RQ's queues and registries, and re-enqueues the lost."""

    def __init__(self, lifecycle: JobLifecycle, settings: Settings) -> None:
        self.lifecycle = lifecycle
        self.client: redis.Redis = lifecycle.client
        self.settings = settings
        self._queues = {name: Queue(name, connection=self.client) for name in PRIORITY_QUEUES.values()}

    def stranded_rq_jobs(self) -> dict[str, str]:
        """RQ jobs of unfinished hgrender jobs that nothing will ever run: ``{rq id: reason}``.

        A chunk or merge is live when RQ has it where its status says (queued: in its queue or the
        worker's intermediate list; started: in the StartedJobRegistry; scheduled: in the
        ScheduledJobRegistry; deferred: some chunk still unfinished). Everything else (missing from Redis,
        queued in no queue, a deferred merge whose chunks all ended) is stranded: what a crash between
        two non-atomic steps, or a Redis restart from a slightly older AOF, can leave behind."""
        live: set[str] = set()
        for queue in self._queues.values():
            live |= set(queue.get_job_ids()) | set(queue.intermediate_queue.get_job_ids())
            # Without RQ's cleanup: abandoned chunks are the workers' to retry (their exception handlers
            # also fail the job of a final step that died on its last attempt).
            live |= set(queue.started_job_registry.get_job_ids(cleanup=False))
            live |= set(queue.scheduled_job_registry.get_job_ids(cleanup=False))
        stranded: dict[str, str] = {}
        for job_id in self.lifecycle.unfinished_job_ids():
            record = self.lifecycle.record(job_id)
            if record is None:  # deleted meanwhile
                continue
            ids = rq_ids(job_id, record.chunk_count)
            fetched = RQJob.fetch_many(ids, connection=self.client)
            statuses = {
                rq_id: job.get_status(refresh=False) if job else None
                for rq_id, job in zip(ids, fetched, strict=True)
            }
            for rq_id, status in statuses.items():
                if status is None:
                    stranded[rq_id] = "missing"
                elif status == RQJobStatus.DEFERRED:
                    if all(statuses[c] in _RQ_ENDED for c in ids[:-1]):
                        stranded[rq_id] = "deferred after its chunks ended"
                elif status not in _RQ_ENDED and rq_id not in live:
                    stranded[rq_id] = f"{status.value} but in no queue or registry"
        return stranded

    def reconcile(self, confirm_after_s: float = 2.0) -> dict[str, str]:
        """Re-enqueue the stranded RQ jobs of unfinished jobs (``stranded_rq_jobs``), at the front of their
        queue; recreate those missing from Redis. Run on start and after a Redis restart, while workers may
        be running: only what is found stranded twice, ``confirm_after_s`` apart and in the same state, is
        touched (a chunk moving between a queue and a registry looks stranded for an instant). One
        reconciliation at a time (a lock). Returns what was re-enqueued, with why."""
        if not self.client.set(RECONCILE_LOCK, "1", nx=True, ex=60):
            return {}
        try:
            first = self.stranded_rq_jobs()
            if first and confirm_after_s > 0:
                time.sleep(confirm_after_s)
            confirmed = {k: v for k, v in self.stranded_rq_jobs().items() if first.get(k) == v}
            for rq_id in confirmed:
                self._revive(rq_id)
            return confirmed
        finally:
            self.client.delete(RECONCILE_LOCK)

    def _revive(self, rq_id: str) -> None:
        """Put one stranded RQ job (``<id>-chunk-<i>`` or ``<id>-merge``) at the front of its queue."""
        job_id = rq_id.split("-", 1)[0]
        record = self.lifecycle.record(job_id)
        if record is None:  # deleted since it was found stranded
            return
        queue = self._queues[PRIORITY_QUEUES[record.priority]]
        try:
            rq_job = RQJob.fetch(rq_id, connection=self.client)
        except NoSuchJobError:
            self._recreate(job_id, record.chunk_count, rq_id, queue.name)
            return
        # RQ's own enqueue step, without its dependency check: the merge's chunks were seen ended (and
        # its check reads RQ's dependency bookkeeping, which may be what was lost).
        queue._enqueue_job(rq_job, at_front=True)

    def _recreate(self, job_id: str, chunk_count: int, rq_id: str, queue_name: str) -> None:
        """Recreate a lost RQ job the way ``create`` made it, then put it at the front of its queue."""
        with self.client.pipeline() as pipe:
            pipe.multi()
            enqueue_job_graph(pipe, self._queues[queue_name], job_id, chunk_count, self.settings, only=rq_id)
            pipe.execute()
        if rq_id == merge_rq_id(job_id) and chunk_count > 1:
            chunks = RQJob.fetch_many(rq_ids(job_id, chunk_count)[:-1], connection=self.client)
            if all(c is not None and c.get_status(refresh=False) in _RQ_ENDED for c in chunks):
                merge = RQJob.fetch(rq_id, connection=self.client)
                self._queues[queue_name]._enqueue_job(merge, at_front=True)  # nobody else will
