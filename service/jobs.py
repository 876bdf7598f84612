"""The API's operations on jobs: create (validate the plan, idempotency, one transaction for the record
and the RQ job graph), read and list views, cancel and delete. The job's keys, records, transitions and
events belong to ``hgcore.jobs.lifecycle.JobLifecycle``, which this class composes (the workers use it
too); the job graph is ``hgcore.jobs.queue_graph``'s; statuses ``hgcore.jobs.status``'.
"""

from __future__ import annotations

import contextlib
import time
import uuid
from collections.abc import Mapping
from typing import Any

from rq import Queue
from rq.command import send_stop_job_command
from rq.exceptions import InvalidJobOperation, NoSuchJobError
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from hgcore.artifacts.keys import input_key, job_prefix
from hgcore.errors import InputError
from hgcore.jobs.keys import idempotency_key as idempotency_redis_key
from hgcore.jobs.lifecycle import JobLifecycle, JobNotFoundError
from hgcore.jobs.queue_graph import PRIORITY_QUEUES, enqueue_job_graph, rq_ids
from hgcore.jobs.record import JobRecord, JobSteps
from hgcore.jobs.status import JobStatus, Priority
from hgcore.jobs.views import JobView, build_view
from hgcore.noise_target import NoiseTarget
from hgcore.settings import Settings
from schemas import Scene

_IDEMPOTENCY_WAIT_S = 2.0


class JobConflictError(Exception):
    """The operation does not apply in the job's current status (HTTP 409)."""


class JobService:
    """Create, read, list, cancel and delete jobs: the API's side of ``JobLifecycle``."""

    def __init__(self, lifecycle: JobLifecycle, settings: Settings) -> None:
        self.lifecycle = lifecycle
        self.client = lifecycle.client
        self.store = lifecycle.store
        self.settings = settings
        # Queue objects cache the server version RQ asks for on every enqueue.
        self._queues = {name: Queue(name, connection=self.client) for name in PRIORITY_QUEUES.values()}

    # ---- creation -------------------------------------------------------------------------------------

    def plan(self, spp: int, chunks: int | None, noise_target: NoiseTarget | None = None) -> int:
        """Number of chunks for a request: the request's, else the default, never more than spp. A
        noise-target job is one chunk: its horse adds passes until the target is met."""
        if noise_target is not None:
            if chunks is not None and chunks > 1:
                raise InputError("chunks: a job with a noise target renders as one chunk")
            return 1
        chunk_count = chunks if chunks is not None else self.settings.default_chunks
        if chunk_count > self.settings.max_chunks:
            raise InputError(f"chunks: {chunk_count} exceeds the limit of {self.settings.max_chunks}")
        return min(chunk_count, spp)  # every chunk needs at least one sample per pixel

    def create(
        self,
        scene: Scene,
        owner: str,
        *,
        priority: Priority = "normal",
        chunks: int | None = None,
        noise_target: NoiseTarget | None = None,
        idempotency_key: str | None = None,
        name: str | None = None,
        extra_files: Mapping[str, bytes] | None = None,
    ) -> tuple[JobView, bool]:
        """Persist a validated scene (its ``film.spp`` and ``film.seed`` are the job's; its document,
        ``Scene.to_json_dict``, is what the lifecycle stores) and enqueue its chunks and merge step.

        Returns (job, created); ``created`` is False when ``idempotency_key`` named an earlier job.
        ``extra_files`` (relative names → bytes) are stored next to the scene (textures of a USD bundle).
        ``noise_target``: render until it is met (``hgcore.noise_target``), as one chunk.
        """
        if priority not in PRIORITY_QUEUES:
            raise InputError(f"priority: must be one of {list(PRIORITY_QUEUES)}")
        film = scene.film
        chunk_count = self.plan(film.spp, chunks, noise_target)
        job_id = uuid.uuid4().hex
        if idempotency_key is not None:
            earlier = self._claim_idempotency_key(owner, idempotency_key, job_id)
            if earlier is not None:
                return earlier, False
        for relative_name, data in (extra_files or {}).items():
            self.store.put_bytes(input_key(job_id, relative_name), data)
        now = time.time()
        record = JobRecord(
            id=job_id,
            owner=owner,
            name=name or None,
            status=JobStatus.QUEUED,
            priority=priority,
            spp=film.spp,
            width=film.width,
            height=film.height,
            seed=film.seed,
            chunk_count=chunk_count,
            target_rel_error=noise_target.rel_error if noise_target is not None else None,
            time_budget_s=noise_target.time_budget_s if noise_target is not None else None,
            target_quantile=noise_target.quantile if noise_target is not None else None,
            created_at=now,
        )
        # One MULTI/EXEC: the record, the scene and every RQ job appear together, and the merge step is
        # registered as a dependent before any chunk exists that could finish.
        try:
            self._commit(record, scene.to_json_dict())
        except Exception:
            self.store.delete_prefix(job_prefix(job_id))  # uploaded bundle files, if any
            raise
        steps = JobSteps.from_hash(JobSteps.initial_hash(chunk_count), chunk_count)
        return build_view(record, steps, now), True

    def _claim_idempotency_key(self, owner: str, idempotency_key: str, job_id: str) -> JobView | None:
        """Claim the key for ``job_id``; if an earlier request holds it, return that job (waiting up to
        ``_IDEMPOTENCY_WAIT_S`` for a concurrent request to commit it). A claim whose job never appeared
        (its request failed) is taken over."""
        key = idempotency_redis_key(owner, idempotency_key)
        ttl_s = self.settings.idempotency_ttl_s
        if self.client.set(key, job_id, nx=True, ex=ttl_s):
            return None
        deadline = time.monotonic() + _IDEMPOTENCY_WAIT_S
        while True:
            existing = self.client.get(key)
            view = self.get(existing.decode()) if existing else None
            if view is not None:
                return view
            if time.monotonic() > deadline:
                self.client.set(key, job_id, ex=ttl_s)
                return None
            time.sleep(0.05)

    def _commit(self, record: JobRecord, scene: dict[str, Any]) -> None:
        with self.client.pipeline() as pipe:
            pipe.multi()
            self.lifecycle.add_to(pipe, record, scene)
            queue = self._queues[PRIORITY_QUEUES[record.priority]]
            enqueue_job_graph(pipe, queue, record.id, record.chunk_count, self.settings)
            pipe.execute()

    # ---- reading --------------------------------------------------------------------------------------

    def get(self, job_id: str) -> JobView | None:
        return self.lifecycle.view(job_id)

    async def aget(self, job_id: str) -> JobView | None:
        return await self.lifecycle.aview(job_id)

    def scene(self, job_id: str) -> dict[str, Any]:
        return self.lifecycle.scene(job_id)

    def list(
        self, owner: str | None, status: JobStatus | None, offset: int, limit: int
    ) -> tuple[list[JobView], int]:
        """Jobs newest first, of one owner (None: all), optionally of one status; (page, total)."""
        return self.lifecycle.list_views(owner, status, offset, limit)

    # ---- cancel and delete ----------------------------------------------------------------------------

    def cancel(self, job_id: str) -> JobView:
        """Mark the job canceled, drop its queued RQ jobs and stop the running ones (the work horse is
        killed; the render also polls the status and stops by itself)."""
        view = self.get(job_id)
        if view is None:
            raise JobNotFoundError(job_id)
        if not self.lifecycle.cancel(job_id):
            current = self.get(job_id)
            assert current is not None
            if current.status == JobStatus.CANCELED:
                return current
            raise JobConflictError(f"status: job is already {current.status.value}")
        for rq_id in rq_ids(job_id, view.chunks_total):
            self._stop_rq_job(rq_id)
        self.lifecycle.close_unfinished_steps(job_id)
        current = self.get(job_id)
        assert current is not None
        return current

    def _stop_rq_job(self, rq_id: str) -> None:
        try:
            rq_job = RQJob.fetch(rq_id, connection=self.client)
        except NoSuchJobError:
            return
        status = rq_job.get_status(refresh=False)
        if status == RQJobStatus.STARTED:
            with contextlib.suppress(InvalidJobOperation):  # it may finish between the two calls
                send_stop_job_command(self.client, rq_id)
        elif status in {RQJobStatus.QUEUED, RQJobStatus.DEFERRED, RQJobStatus.SCHEDULED}:
            with contextlib.suppress(InvalidJobOperation):
                rq_job.cancel()

    def delete(self, job_id: str) -> None:
        """Remove the job everywhere: stop it if needed, then its RQ jobs, record, indexes, artifacts."""
        record = self.lifecycle.record(job_id)
        if record is not None and not record.is_final:
            self.cancel(job_id)
        chunk_count = record.chunk_count if record is not None else 0
        for rq_id in rq_ids(job_id, chunk_count):
            with contextlib.suppress(NoSuchJobError):
                RQJob.fetch(rq_id, connection=self.client).delete()
        self.lifecycle.remove(job_id)
        self.store.delete_prefix(job_prefix(job_id))
