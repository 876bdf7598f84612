"""Render jobs: records in Redis, the status state machine, chunk planning, enqueueing, cancel and delete,
and progress aggregated over chunks.

A job of ``K > 1`` chunks becomes ``K`` RQ chunk jobs (``<id>-chunk-<i>``; the worker renders spp
partition ``i`` of ``worker.render.api.plan_chunks(spp, K, seed)``, each with its own seed) on the queue its
priority names, plus one merge job (``<id>-merge``) that depends on all chunks (failures allowed, so the
merge step is also where a failed chunk fails the job). A job of one chunk becomes a single RQ job under the
merge job's id that renders and merges in one work horse: no partial upload, and one dequeue and fork
instead of two (half the queue's latency for small jobs). Either way ``<id>-merge`` is the job's final step,
the one regression evaluations depend on. Redis layout, all under ``hgrender:``:

``job:<id>``            hash: the record (owner, status, priority, spp, seed, chunks, timestamps, error)
``job:<id>:scene``      string: the validated scene document (JSON)
``job:<id>:chunks``     hash: ``<i>.<field>`` per chunk (status, progress, worker, attempts, samples, ...)
                        and ``merge.<field>``, written by the workers
``jobs`` / ``jobs:owner:<o>``  sorted sets of ids by creation time (listing, pagination)
``jobs:by_state``       hash: number of jobs in each status (metrics), kept by the transition script
``events:<id>``         pub/sub channel of progress and status events (SSE)

Status machine: ``queued → running → succeeded | failed``; ``queued | running → canceled``; final states
never change. Every transition is one Lua script call, so concurrent workers and the API cannot race.
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
from rq import Queue, Retry
from rq.command import send_stop_job_command
from rq.exceptions import InvalidJobOperation, NoSuchJobError
from rq.job import Dependency
from rq.job import Job as RQJob
from rq.job import JobStatus as RQJobStatus

from service.core.config import Settings
from service.models import (
    TERMINAL_STATUSES,
    ChunkView,
    JobStatus,
    JobTimings,
    JobView,
    Priority,
)
from service.store.base import ArtifactNotFoundError, ArtifactStore

PRIORITY_QUEUES: dict[str, str] = {"high": "high", "normal": "default", "low": "low"}
CHUNK_TASK = "worker.tasks.render_chunk_task"
MERGE_TASK = "worker.tasks.merge_task"
RENDER_JOB_TASK = "worker.tasks.render_job_task"
FINAL_STEP_TASKS = frozenset({MERGE_TASK, RENDER_JOB_TASK})
"""Tasks that end a job: when one fails for good, the job fails (``worker.tasks.fail_job``)."""

_JOB_KEY = "hgrender:job:{}"
_CHUNKS_KEY = "hgrender:job:{}:chunks"
_SCENE_KEY = "hgrender:job:{}:scene"
_INDEX_KEY = "hgrender:jobs"
_OWNER_INDEX_KEY = "hgrender:jobs:owner:{}"
_BY_STATE_KEY = "hgrender:jobs:by_state"
_IDEMPOTENCY_KEY = "hgrender:idempotency:{}:{}"
EVENTS_CHANNEL = "hgrender:events:{}"
_IDEMPOTENCY_WAIT_S = 2.0
_RECONCILE_LOCK_KEY = "hgrender:reconcile-lock"
_RQ_ENDED = frozenset({RQJobStatus.FINISHED, RQJobStatus.FAILED, RQJobStatus.STOPPED, RQJobStatus.CANCELED})

# KEYS: job hash, by-state hash. ARGV: new status, n allowed, allowed..., then field/value pairs to set.
# Returns the previous status, or false when the job is missing or the transition is not allowed.
_TRANSITION_LUA = """
local current = redis.call('HGET', KEYS[1], 'status')
if not current then return false end
local n = tonumber(ARGV[2])
for i = 3, 2 + n do
  if ARGV[i] == current then
    redis.call('HSET', KEYS[1], 'status', ARGV[1])
    for j = 3 + n, #ARGV, 2 do redis.call('HSET', KEYS[1], ARGV[j], ARGV[j + 1]) end
    redis.call('HINCRBY', KEYS[2], current, -1)
    redis.call('HINCRBY', KEYS[2], ARGV[1], 1)
    return current
  end
end
return false
"""

# KEYS: job hash. ARGV: progress, channel, payload. Publishes the payload only when the progress exceeds
# every progress published before for this job: chunks on different workers aggregate concurrently, and a
# retried chunk restarts at 0, but a job's published progress never goes backwards.
_PUBLISH_PROGRESS_LUA = """
local last = tonumber(redis.call('HGET', KEYS[1], 'progress_published') or '-1')
local progress = tonumber(ARGV[1])
if progress <= last then return 0 end
redis.call('HSET', KEYS[1], 'progress_published', ARGV[1])
redis.call('PUBLISH', ARGV[2], ARGV[3])
return 1
"""

ALLOWED_FROM: dict[JobStatus, tuple[JobStatus, ...]] = {
    JobStatus.RUNNING: (JobStatus.QUEUED,),
    JobStatus.SUCCEEDED: (JobStatus.QUEUED, JobStatus.RUNNING),
    JobStatus.FAILED: (JobStatus.QUEUED, JobStatus.RUNNING),
    JobStatus.CANCELED: (JobStatus.QUEUED, JobStatus.RUNNING),
}


class JobNotFoundError(KeyError):
    """No job with this id (or not visible to the caller)."""


class JobConflictError(Exception):
    """The operation does not apply in the job's current status (HTTP 409)."""


def chunk_rq_id(job_id: str, index: int) -> str:
    return f"{job_id}-chunk-{index}"


def merge_rq_id(job_id: str) -> str:
    """RQ id of the job's final step: its merge, or its only step when it has one chunk."""
    return f"{job_id}-merge"


def rq_ids(job_id: str, chunk_count: int) -> list[str]:
    chunk_ids = [chunk_rq_id(job_id, i) for i in range(chunk_count)] if chunk_count > 1 else []
    return [*chunk_ids, merge_rq_id(job_id)]


def scene_key(job_id: str) -> str:
    """Store key of the scene's provenance copy, written with the final artifacts."""
    return f"jobs/{job_id}/scene.json"


def chunk_key(job_id: str, index: int) -> str:
    return f"jobs/{job_id}/chunks/{index}.npz"


def artifact_prefix(job_id: str) -> str:
    return f"jobs/{job_id}/"


def _decode(mapping: Mapping[bytes, bytes]) -> dict[str, str]:
    return {k.decode(): v.decode() for k, v in mapping.items()}


def _float_or_none(value: str | None) -> float | None:
    return float(value) if value not in (None, "") else None


class JobService:
    """Operations on jobs, shared by the API (``service.api``) and the queue tasks (``worker.tasks``)."""

    def __init__(
        self,
        client: redis.Redis,
        store: ArtifactStore,
        settings: Settings,
        aclient: aioredis.Redis | None = None,
    ) -> None:
        self.client = client
        self.aclient = aclient  # the API's asyncio client, for the hot read path (aget)
        self.store = store
        self.settings = settings
        self._transition_script = client.register_script(_TRANSITION_LUA)
        self._publish_progress_script = client.register_script(_PUBLISH_PROGRESS_LUA)
        # Queue objects cache the server version RQ asks for on every enqueue.
        self._queues = {name: Queue(name, connection=client) for name in PRIORITY_QUEUES.values()}

    # ---- creation -------------------------------------------------------------------------------------

    def plan(self, spp: int, chunks: int | None) -> int:
        """Number of chunks for a request: the request's, else the default, never more than spp."""
        chunk_count = chunks if chunks is not None else self.settings.default_chunks
        if chunk_count > self.settings.max_chunks:
            raise ValueError(f"chunks: {chunk_count} exceeds the limit of {self.settings.max_chunks}")
        return min(chunk_count, spp)  # every chunk needs at least one sample per pixel

    def create(
        self,
        scene: dict[str, Any],
        owner: str,
        *,
        priority: Priority = "normal",
        chunks: int | None = None,
        idempotency_key: str | None = None,
        name: str | None = None,
        extra_files: Mapping[str, bytes] | None = None,
    ) -> tuple[JobView, bool]:
        """Persist a validated scene (its ``film.spp`` and ``film.seed`` are the job's) and enqueue its
        chunks and merge step.

        Returns (job, created); ``created`` is False when ``idempotency_key`` named an earlier job.
        ``extra_files`` (relative names → bytes) are stored next to the scene (textures of a USD bundle).
        """
        if priority not in PRIORITY_QUEUES:
            raise ValueError(f"priority: must be one of {list(PRIORITY_QUEUES)}")
        spp = int(scene["film"]["spp"])
        base_seed = int(scene["film"].get("seed", 0))
        chunk_count = self.plan(spp, chunks)
        job_id = uuid.uuid4().hex
        if idempotency_key is not None:
            earlier = self._claim_idempotency_key(owner, idempotency_key, job_id)
            if earlier is not None:
                return earlier, False
        for relative_name, data in (extra_files or {}).items():
            self.store.put_bytes(f"jobs/{job_id}/input/{relative_name}", data)
        now = time.time()
        record = {
            "id": job_id,
            "owner": owner,
            "name": name or "",
            "status": JobStatus.QUEUED.value,
            "priority": priority,
            "spp": str(spp),
            "seed": str(base_seed),
            "chunks": str(chunk_count),
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
            self.store.delete_prefix(artifact_prefix(job_id))  # uploaded bundle files, if any
            raise
        view = build_view(record, {f"{i}.status": "queued" for i in range(chunk_count)}, now)
        return view, True

    def _claim_idempotency_key(self, owner: str, idempotency_key: str, job_id: str) -> JobView | None:
        """Claim the key for ``job_id``; if an earlier request holds it, return that job (waiting up to
        ``_IDEMPOTENCY_WAIT_S`` for a concurrent request to commit it). A claim whose job never appeared
        (its request failed) is taken over."""
        key = _IDEMPOTENCY_KEY.format(owner, idempotency_key)
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
            pipe.hset(_JOB_KEY.format(job_id), mapping=record)
            pipe.set(_SCENE_KEY.format(job_id), json.dumps(scene, separators=(",", ":")))
            pipe.hset(
                _CHUNKS_KEY.format(job_id), mapping={f"{i}.status": "queued" for i in range(chunk_count)}
            )
            pipe.zadd(_INDEX_KEY, {job_id: now})
            pipe.zadd(_OWNER_INDEX_KEY.format(owner), {job_id: now})
            pipe.hincrby(_BY_STATE_KEY, JobStatus.QUEUED.value, 1)
            self._enqueue(pipe, job_id, chunk_count, PRIORITY_QUEUES[priority])
            pipe.execute()

    def _enqueue(
        self,
        pipe: redis.client.Pipeline,
        job_id: str,
        chunk_count: int,
        queue_name: str,
        only: str | None = None,
    ) -> None:
        """Add the chunk jobs (queued) and the merge job (deferred on all chunks, failures allowed), or
        for a one-chunk job the single job that renders and merges. ``only``: recreate just that RQ job
        (reconciliation), at the front of the queue."""
        queue = self._queues[queue_name]
        # Finished work first: a retry goes to the front of its queue, and so does a merge once its last
        # chunk ended, so a backlog of new chunks delays neither (jobs finish in submission order).
        retry = (
            Retry(
                max=self.settings.chunk_retry_max,
                interval=self.settings.chunk_retry_intervals_s,
                enqueue_at_front=True,
            )
            if self.settings.chunk_retry_max > 0
            else None
        )
        common: dict[str, Any] = {
            "timeout": self.settings.job_timeout_s,
            "result_ttl": self.settings.result_ttl_s,
            "failure_ttl": self.settings.result_ttl_s,
            "retry": retry,
        }
        if chunk_count == 1:
            steps = [(RENDER_JOB_TASK, (job_id,), merge_rq_id(job_id), f"render and merge job {job_id}")]
        else:
            steps = [
                (
                    CHUNK_TASK,
                    (job_id, index),
                    chunk_rq_id(job_id, index),
                    f"render chunk {index} of job {job_id}",
                )
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

    def scene(self, job_id: str) -> dict[str, Any]:
        """The job's validated scene document: kept in Redis with the record (so a submission touches no
        disk), and copied to the store as ``scene.json`` with the final artifacts."""
        data = self.client.get(_SCENE_KEY.format(job_id))
        if data is None:
            try:
                data = self.store.get_bytes(scene_key(job_id))
            except ArtifactNotFoundError:
                raise JobNotFoundError(job_id) from None
        return json.loads(data)

    # ---- reading --------------------------------------------------------------------------------------

    def get(self, job_id: str) -> JobView | None:
        """The job's current view, or (when Redis lost it) the one in its manifest; None if unknown."""
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hgetall(_JOB_KEY.format(job_id))
            pipe.hgetall(_CHUNKS_KEY.format(job_id))
            record, chunk_fields = pipe.execute()
        if record:
            return build_view(_decode(record), _decode(chunk_fields))
        return self._view_from_manifest(job_id)

    async def aget(self, job_id: str) -> JobView | None:
        """``get`` on the asyncio client (the API's most frequent request stays off the thread pool)."""
        if self.aclient is None:
            raise RuntimeError("aclient: JobService was built without an asyncio Redis client")
        async with self.aclient.pipeline(transaction=False) as pipe:
            pipe.hgetall(_JOB_KEY.format(job_id))
            pipe.hgetall(_CHUNKS_KEY.format(job_id))
            record, chunk_fields = await pipe.execute()
        if record:
            return build_view(_decode(record), _decode(chunk_fields))
        return await asyncio.to_thread(self._view_from_manifest, job_id)

    def _view_from_manifest(self, job_id: str) -> JobView | None:
        if not job_id.isalnum():
            return None
        try:
            manifest = json.loads(self.store.get_bytes(f"jobs/{job_id}/manifest.json"))
        except (ArtifactNotFoundError, ValueError):
            return None
        return JobView.model_validate(manifest["job"])

    def list(
        self, owner: str | None, status: JobStatus | None, offset: int, limit: int
    ) -> tuple[list[JobView], int]:
        """Jobs newest first, of one owner (None: all), optionally of one status; (page, total)."""
        index = _INDEX_KEY if owner is None else _OWNER_INDEX_KEY.format(owner)
        if status is None:
            total = int(self.client.zcard(index))
            ids = [i.decode() for i in self.client.zrevrange(index, offset, offset + limit - 1)]
            return self._views(ids), total
        # Filtering by status scans the owner's index; statuses live in the records.
        ids = [i.decode() for i in self.client.zrevrange(index, 0, -1)]
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in ids:
                pipe.hget(_JOB_KEY.format(job_id), "status")
            statuses = pipe.execute()
        matching = [i for i, s in zip(ids, statuses, strict=True) if s is not None and s.decode() == status]
        return self._views(matching[offset : offset + limit]), len(matching)

    def _views(self, job_ids: list[str]) -> list[JobView]:
        """Views of several jobs in one round trip (jobs deleted meanwhile are left out)."""
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in job_ids:
                pipe.hgetall(_JOB_KEY.format(job_id))
                pipe.hgetall(_CHUNKS_KEY.format(job_id))
            replies = pipe.execute()
        return [
            build_view(_decode(record), _decode(chunk_fields))
            for record, chunk_fields in zip(replies[::2], replies[1::2], strict=True)
            if record
        ]

    def counts_by_state(self) -> dict[str, int]:
        counts = {k: int(v) for k, v in _decode(self.client.hgetall(_BY_STATE_KEY)).items()}
        return {s.value: counts.get(s.value, 0) for s in JobStatus}

    # ---- transitions ----------------------------------------------------------------------------------

    def transition(self, job_id: str, new_status: JobStatus, **fields: str) -> JobStatus | None:
        """Move the job to ``new_status`` if allowed; returns the previous status, or None if not moved."""
        allowed = [s.value for s in ALLOWED_FROM[new_status]]
        pairs = [str(x) for kv in fields.items() for x in kv]
        previous = self._transition_script(
            keys=[_JOB_KEY.format(job_id), _BY_STATE_KEY],
            args=[new_status.value, len(allowed), *allowed, *pairs],
        )
        if previous is None:
            return None
        self.publish(job_id, {"type": "status", "status": new_status.value})
        return JobStatus(previous.decode())

    def publish(self, job_id: str, event: dict[str, Any]) -> None:
        self.client.publish(EVENTS_CHANNEL.format(job_id), json.dumps(event))

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
            self.client.hset(_CHUNKS_KEY.format(job_id), mapping=unfinished)

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

    # ---- reconciliation --------------------------------------------------------------------------------

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
        for job_id in self._unfinished_job_ids():
            chunk_count = int(self.client.hget(_JOB_KEY.format(job_id), "chunks") or 0)
            ids = rq_ids(job_id, chunk_count)
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

    def _unfinished_job_ids(self) -> list[str]:
        ids = [i.decode() for i in self.client.zrange(_INDEX_KEY, 0, -1)]
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in ids:
                pipe.hget(_JOB_KEY.format(job_id), "status")
            statuses = pipe.execute()
        unfinished = {JobStatus.QUEUED.value.encode(), JobStatus.RUNNING.value.encode()}
        return [i for i, status in zip(ids, statuses, strict=True) if status in unfinished]

    def reconcile(self, confirm_after_s: float = 2.0) -> dict[str, str]:
        """Re-enqueue the stranded RQ jobs of unfinished jobs (``stranded_rq_jobs``), at the front of their
        queue; recreate those missing from Redis. Run on start and after a Redis restart, while workers may
        be running: only what is found stranded twice, ``confirm_after_s`` apart and in the same state, is
        touched (a chunk moving between a queue and a registry looks stranded for an instant). One
        reconciliation at a time (a lock). Returns what was re-enqueued, with why."""
        if not self.client.set(_RECONCILE_LOCK_KEY, "1", nx=True, ex=60):
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
            self.client.delete(_RECONCILE_LOCK_KEY)

    def _revive(self, rq_id: str) -> None:
        """Put one stranded RQ job (``<id>-chunk-<i>`` or ``<id>-merge``) at the front of its queue."""
        job_id = rq_id.split("-", 1)[0]
        record = self.record(job_id)
        queue = self._queues[PRIORITY_QUEUES[record["priority"]]]
        try:
            rq_job = RQJob.fetch(rq_id, connection=self.client)
        except NoSuchJobError:
            self._recreate(job_id, int(record["chunks"]), rq_id, queue.name)
            return
        # RQ's own enqueue step, without its dependency check: the merge's chunks were seen ended (and
        # its check reads RQ's dependency bookkeeping, which may be what was lost).
        queue._enqueue_job(rq_job, at_front=True)

    def _recreate(self, job_id: str, chunk_count: int, rq_id: str, queue_name: str) -> None:
        """Recreate a lost RQ job the way ``create`` made it, then put it at the front of its queue."""
        with self.client.pipeline() as pipe:
            pipe.multi()
            self._enqueue(pipe, job_id, chunk_count, queue_name, only=rq_id)
            pipe.execute()
        if rq_id == merge_rq_id(job_id) and chunk_count > 1:
            chunks = RQJob.fetch_many(rq_ids(job_id, chunk_count)[:-1], connection=self.client)
            if all(c is not None and c.get_status(refresh=False) in _RQ_ENDED for c in chunks):
                merge = RQJob.fetch(rq_id, connection=self.client)
                self._queues[queue_name]._enqueue_job(merge, at_front=True)  # nobody else will

    def delete(self, job_id: str) -> None:
        """Remove the job everywhere: stop it if needed, then its RQ jobs, record, indexes, artifacts."""
        record = _decode(self.client.hgetall(_JOB_KEY.format(job_id)))
        if record and JobStatus(record["status"]) not in TERMINAL_STATUSES:
            self.cancel(job_id)
            record["status"] = JobStatus.CANCELED.value
        chunk_count = int(record.get("chunks", "0") or 0)
        for rq_id in rq_ids(job_id, chunk_count):
            with contextlib.suppress(NoSuchJobError):
                RQJob.fetch(rq_id, connection=self.client).delete()
        with self.client.pipeline() as pipe:
            pipe.delete(_JOB_KEY.format(job_id), _CHUNKS_KEY.format(job_id), _SCENE_KEY.format(job_id))
            pipe.zrem(_INDEX_KEY, job_id)
            if record:
                pipe.zrem(_OWNER_INDEX_KEY.format(record["owner"]), job_id)
                pipe.hincrby(_BY_STATE_KEY, record["status"], -1)
            pipe.execute()
        self.store.delete_prefix(artifact_prefix(job_id))

    # ---- worker-side bookkeeping ----------------------------------------------------------------------

    def record(self, job_id: str) -> dict[str, str]:
        return _decode(self.client.hgetall(_JOB_KEY.format(job_id)))

    def status(self, job_id: str) -> JobStatus | None:
        value = self.client.hget(_JOB_KEY.format(job_id), "status")
        return JobStatus(value.decode()) if value is not None else None

    def chunk_started(
        self, job_id: str, index: int | str, worker: str, pid: int, spp: int | None = None
    ) -> None:
        """A work horse (process ``pid`` of ``worker``) began chunk ``index`` (or ``merge``)."""
        prefix = f"{index}."
        with self.client.pipeline() as pipe:
            pipe.hset(
                _CHUNKS_KEY.format(job_id),
                mapping={
                    prefix + "status": "running",
                    prefix + "progress": "0",
                    prefix + "worker": worker,
                    prefix + "pid": str(pid),
                    prefix + "spp": "" if spp is None else str(spp),
                    prefix + "started_at": repr(time.time()),
                },
            )
            pipe.hincrby(_CHUNKS_KEY.format(job_id), prefix + "attempts", 1)
            pipe.execute()
        self.transition(job_id, JobStatus.RUNNING, started_at=repr(time.time()))

    def chunk_progress(self, job_id: str, index: int, fraction: float) -> None:
        """Store one chunk's progress and publish the job's aggregated progress."""
        fraction = min(1.0, max(0.0, fraction))
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hset(_CHUNKS_KEY.format(job_id), f"{index}.progress", repr(fraction))
            pipe.hgetall(_JOB_KEY.format(job_id))
            pipe.hgetall(_CHUNKS_KEY.format(job_id))
            _, record, chunk_fields = pipe.execute()
        if record:
            view = build_view(_decode(record), _decode(chunk_fields))
            event = {
                "type": "progress",
                "progress": view.progress,
                "chunks_done": view.chunks_done,
                "chunks_total": view.chunks_total,
                "eta_s": view.eta_s,
            }
            self._publish_progress_script(
                keys=[_JOB_KEY.format(job_id)],
                args=[repr(view.progress), EVENTS_CHANNEL.format(job_id), json.dumps(event)],
            )

    def chunk_finished(self, job_id: str, index: int | str, samples: int, seconds: float) -> None:
        """A chunk (or ``merge``) completed: count the completion (tests check it is counted once)."""
        prefix = f"{index}."
        with self.client.pipeline() as pipe:
            pipe.hset(
                _CHUNKS_KEY.format(job_id),
                mapping={
                    prefix + "status": "done",
                    prefix + "progress": "1",
                    prefix + "samples": str(samples),
                    prefix + "seconds": repr(seconds),
                    prefix + "finished_at": repr(time.time()),
                },
            )
            pipe.hincrby(_CHUNKS_KEY.format(job_id), prefix + "completions", 1)
            pipe.incrbyfloat("hgrender:metrics:render_seconds_total", seconds)
            pipe.incrby("hgrender:metrics:samples_total", samples)
            pipe.execute()
        if index != "merge":
            self.chunk_progress(job_id, int(index), 1.0)

    def chunk_fields(self, job_id: str) -> dict[str, str]:
        """The raw ``<i>.<field>`` / ``merge.<field>`` bookkeeping of a job's chunks."""
        return _decode(self.client.hgetall(_CHUNKS_KEY.format(job_id)))

    def chunk_completions(self, job_id: str) -> dict[str, int]:
        """How many times each chunk (and ``merge``) ran to completion."""
        fields = self.chunk_fields(job_id)
        return {
            k.removesuffix(".completions"): int(v) for k, v in fields.items() if k.endswith(".completions")
        }

    def set_chunk_status(self, job_id: str, index: int | str, status: str) -> None:
        self.client.hset(_CHUNKS_KEY.format(job_id), f"{index}.status", status)


def build_view(record: dict[str, str], chunk_fields: dict[str, str], now: float | None = None) -> JobView:
    """Aggregate a record and its chunk fields into the API view (progress = mean chunk fraction)."""
    now = time.time() if now is None else now
    chunk_count = int(record["chunks"])
    status = JobStatus(record["status"])
    chunks = [
        ChunkView(
            index=i,
            status=chunk_fields.get(f"{i}.status", "queued"),  # type: ignore[arg-type]
            progress=float(chunk_fields.get(f"{i}.progress", "0") or 0),
            spp=int(chunk_fields[f"{i}.spp"]) if chunk_fields.get(f"{i}.spp") else None,
            worker=chunk_fields.get(f"{i}.worker") or None,
            attempts=int(chunk_fields.get(f"{i}.attempts", "0")),
            samples=int(chunk_fields[f"{i}.samples"]) if chunk_fields.get(f"{i}.samples") else None,
            seconds=_float_or_none(chunk_fields.get(f"{i}.seconds")),
        )
        for i in range(chunk_count)
    ]
    chunks_done = sum(1 for c in chunks if c.status == "done")
    progress = 1.0 if status == JobStatus.SUCCEEDED else sum(c.progress for c in chunks) / max(1, chunk_count)
    if status != JobStatus.SUCCEEDED:
        progress = min(progress, 0.999)  # the merge step is still to come
    created_at = float(record["created_at"])
    started_at = _float_or_none(record.get("started_at"))
    finished_at = _float_or_none(record.get("finished_at"))
    eta_s = None
    if status == JobStatus.RUNNING and started_at is not None and progress > 0:
        eta_s = max(0.0, (now - started_at) * (1.0 - progress) / progress)
    render_seconds = [c.seconds for c in chunks if c.seconds is not None]
    workers = sorted({c.worker for c in chunks if c.worker} | {chunk_fields.get("merge.worker") or ""} - {""})
    return JobView(
        id=record["id"],
        owner=record["owner"],
        name=record.get("name") or None,
        status=status,
        progress=progress,
        eta_s=eta_s,
        priority=record["priority"],  # type: ignore[arg-type]
        spp=int(record["spp"]),
        seed=int(record["seed"]),
        chunks_total=chunk_count,
        chunks_done=chunks_done,
        workers=workers,
        error=record.get("error") or None,
        timings=JobTimings(
            created_at=created_at,
            started_at=started_at,
            finished_at=finished_at,
            queue_wait_s=started_at - created_at if started_at is not None else None,
            render_s=sum(render_seconds) if render_seconds else None,
            merge_s=_float_or_none(chunk_fields.get("merge.seconds")),
            total_s=finished_at - created_at if finished_at is not None else None,
        ),
        chunks=chunks,
    )
