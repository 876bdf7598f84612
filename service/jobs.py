"""The API's operations on jobs: create (validate the plan, idempotency, one transaction for the record
and the RQ job graph), read and list views, cancel and delete. Records, transitions, events and the chunk
bookkeeping live in ``hgcore.jobs.records.JobRecords``, which this class extends; the job graph in
``hgcore.jobs.queue_graph``; statuses in ``hgcore.jobs.status``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
import uuid
from collections.abc import Mapping
from typing import Any

import redis
import redis.asyncio as aioredis
from rq import Queue
from rq.command import send_stop_job_command
from rq.exceptions import InvalidJobOperation, NoSuchJobError
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from hgcore.artifacts.keys import input_key, job_prefix
from hgcore.errors import InputError
from hgcore.jobs.keys import (
    JOBS_BY_STATE,
    JOBS_INDEX,
    chunks_key,
    job_key,
    owner_index_key,
    scene_document_key,
)
from hgcore.jobs.keys import idempotency_key as idempotency_redis_key
from hgcore.jobs.queue_graph import PRIORITY_QUEUES, enqueue_job_graph, rq_ids
from hgcore.jobs.records import JobNotFoundError, JobRecords, decode_hash
from hgcore.jobs.status import TERMINAL_STATUSES, JobStatus, Priority
from hgcore.jobs.views import JobView, build_view
from hgcore.noise_target import NoiseTarget
from hgcore.settings import Settings
from hgcore.store.base import ArtifactStore

_IDEMPOTENCY_WAIT_S = 2.0
_RQ_ENDED = frozenset({RQJobStatus.FINISHED, RQJobStatus.FAILED, RQJobStatus.STOPPED, RQJobStatus.CANCELED})


class JobConflictError(Exception):
    """The operation does not apply in the job's current status (HTTP 409)."""


class JobService(JobRecords):
    """Create, read, list, cancel and delete jobs (the API's side; workers use ``JobRecords``)."""

    def __init__(
        self,
        client: redis.Redis,
        store: ArtifactStore,
        settings: Settings,
        aclient: aioredis.Redis | None = None,
    ) -> None:
        super().__init__(client, store, settings)
        self.aclient = aclient  # the API's asyncio client, for the hot read path (aget)
        # Queue objects cache the server version RQ asks for on every enqueue.
        self._queues = {name: Queue(name, connection=client) for name in PRIORITY_QUEUES.values()}

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
        scene: dict[str, Any],
        owner: str,
        *,
        priority: Priority = "normal",
        chunks: int | None = None,
        noise_target: NoiseTarget | None = None,
        idempotency_key: str | None = None,
        name: str | None = None,
        extra_files: Mapping[str, bytes] | None = None,
    ) -> tuple[JobView, bool]:
        """Persist a validated scene (its ``film.spp`` and ``film.seed`` are the job's) and enqueue its
        chunks and merge step.

        Returns (job, created); ``created`` is False when ``idempotency_key`` named an earlier job.
        ``extra_files`` (relative names → bytes) are stored next to the scene (textures of a USD bundle).
        ``noise_target``: render until it is met (``hgcore.noise_target``), as one chunk.
        """
        if priority not in PRIORITY_QUEUES:
            raise InputError(f"priority: must be one of {list(PRIORITY_QUEUES)}")
        spp = int(scene["film"]["spp"])
        base_seed = int(scene["film"].get("seed", 0))
        chunk_count = self.plan(spp, chunks, noise_target)
        job_id = uuid.uuid4().hex
        if idempotency_key is not None:
            earlier = self._claim_idempotency_key(owner, idempotency_key, job_id)
            if earlier is not None:
                return earlier, False
        for relative_name, data in (extra_files or {}).items():
            self.store.put_bytes(input_key(job_id, relative_name), data)
        now = time.time()
        record = {
            "id": job_id,
            "owner": owner,
            "name": name or "",
            "status": JobStatus.QUEUED.value,
            "priority": priority,
            "spp": str(spp),
            "width": str(scene["film"].get("width", "")),
            "height": str(scene["film"].get("height", "")),
            "seed": str(base_seed),
            "chunks": str(chunk_count),
            **(noise_target.record_fields() if noise_target is not None else {}),
            "created_at": repr(now),
            "started_at": "",
            "finished_at": "",
            "error": "",
        }
        # One MULTI/EXEC: the record, the scene and every RQ job appear together, and the merge step is
        # registered as a dependent before any chunk exists that could finish.
        try:
            self._commit(job_id, owner, record, scene, chunk_count, priority, now)
        except Exception:
            self.store.delete_prefix(job_prefix(job_id))  # uploaded bundle files, if any
            raise
        view = build_view(record, {f"{i}.status": "queued" for i in range(chunk_count)}, now)
        return view, True

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

    def _commit(
        self,
        job_id: str,
        owner: str,
        record: dict[str, str],
        scene: dict[str, Any],
        chunk_count: int,
        priority: str,
        now: float,
    ) -> None:
        with self.client.pipeline() as pipe:
            pipe.multi()
            pipe.hset(job_key(job_id), mapping=record)
            pipe.set(scene_document_key(job_id), json.dumps(scene, separators=(",", ":")))
            pipe.hset(chunks_key(job_id), mapping={f"{i}.status": "queued" for i in range(chunk_count)})
            pipe.zadd(JOBS_INDEX, {job_id: now})
            pipe.zadd(owner_index_key(owner), {job_id: now})
            pipe.hincrby(JOBS_BY_STATE, JobStatus.QUEUED.value, 1)
            queue = self._queues[PRIORITY_QUEUES[priority]]
            enqueue_job_graph(pipe, queue, job_id, chunk_count, self.settings)
            pipe.execute()

    # ---- reading --------------------------------------------------------------------------------------

    async def aget(self, job_id: str) -> JobView | None:
        """``get`` on the asyncio client (the API's most frequent request stays off the thread pool)."""
        if self.aclient is None:
            raise RuntimeError("aclient: JobService was built without an asyncio Redis client")
        async with self.aclient.pipeline(transaction=False) as pipe:
            pipe.hgetall(job_key(job_id))
            pipe.hgetall(chunks_key(job_id))
            record, chunk_fields = await pipe.execute()
        if record:
            return build_view(decode_hash(record), decode_hash(chunk_fields))
        return await asyncio.to_thread(self._view_from_manifest, job_id)

    def list(
        self, owner: str | None, status: JobStatus | None, offset: int, limit: int
    ) -> tuple[list[JobView], int]:
        """Jobs newest first, of one owner (None: all), optionally of one status; (page, total)."""
        index = JOBS_INDEX if owner is None else owner_index_key(owner)
        if status is None:
            total = int(self.client.zcard(index))
            ids = [i.decode() for i in self.client.zrevrange(index, offset, offset + limit - 1)]
            return self._views(ids), total
        # Filtering by status scans the owner's index; statuses live in the records.
        ids = [i.decode() for i in self.client.zrevrange(index, 0, -1)]
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in ids:
                pipe.hget(job_key(job_id), "status")
            statuses = pipe.execute()
        matching = [i for i, s in zip(ids, statuses, strict=True) if s is not None and s.decode() == status]
        return self._views(matching[offset : offset + limit]), len(matching)

    def _views(self, job_ids: list[str]) -> list[JobView]:
        """Views of several jobs in one round trip (jobs deleted meanwhile are left out)."""
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in job_ids:
                pipe.hgetall(job_key(job_id))
                pipe.hgetall(chunks_key(job_id))
            replies = pipe.execute()
        return [
            build_view(decode_hash(record), decode_hash(chunk_fields))
            for record, chunk_fields in zip(replies[::2], replies[1::2], strict=True)
            if record
        ]

    def counts_by_state(self) -> dict[str, int]:
        counts = {k: int(v) for k, v in decode_hash(self.client.hgetall(JOBS_BY_STATE)).items()}
        return {s.value: counts.get(s.value, 0) for s in JobStatus}

    # ---- cancel and delete ----------------------------------------------------------------------------

    def cancel(self, job_id: str) -> JobView:
        """Mark the job canceled, drop its queued RQ jobs and stop the running ones (the work horse is
        killed; the render also polls the status and stops by itself)."""
        view = self.get(job_id)
        if view is None:
            raise JobNotFoundError(job_id)
        if self.transition(job_id, JobStatus.CANCELED, finished_at=repr(time.time())) is None:
            current = self.get(job_id)
            assert current is not None
            if current.status == JobStatus.CANCELED:
                return current
            raise JobConflictError(f"status: job is already {current.status.value}")
        for rq_id in rq_ids(job_id, view.chunks_total):
            self._stop_rq_job(rq_id)
        self._mark_unfinished_chunks_canceled(job_id, view.chunks_total)
        current = self.get(job_id)
        assert current is not None
        return current

    def _mark_unfinished_chunks_canceled(self, job_id: str, chunk_count: int) -> None:
        """Chunks (and the merge step) that had not finished read ``canceled``, not ``running`` or
        ``queued`` forever: their RQ jobs were dropped or stopped above."""
        fields = self.chunk_fields(job_id)
        steps = [*(str(i) for i in range(chunk_count)), "merge"]
        unfinished = {
            f"{step}.status": "canceled"
            for step in steps
            if fields.get(f"{step}.status", "queued" if step != "merge" else "") in {"queued", "running"}
        }
        if unfinished:
            self.client.hset(chunks_key(job_id), mapping=unfinished)

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
        record = decode_hash(self.client.hgetall(job_key(job_id)))
        if record and JobStatus(record["status"]) not in TERMINAL_STATUSES:
            self.cancel(job_id)
            record["status"] = JobStatus.CANCELED.value
        chunk_count = int(record.get("chunks", "0") or 0)
        for rq_id in rq_ids(job_id, chunk_count):
            with contextlib.suppress(NoSuchJobError):
                RQJob.fetch(rq_id, connection=self.client).delete()
        with self.client.pipeline() as pipe:
            pipe.delete(job_key(job_id), chunks_key(job_id), scene_document_key(job_id))
            pipe.zrem(JOBS_INDEX, job_id)
            if record:
                pipe.zrem(owner_index_key(record["owner"]), job_id)
                pipe.hincrby(JOBS_BY_STATE, record["status"], -1)
            pipe.execute()
        self.store.delete_prefix(job_prefix(job_id))
