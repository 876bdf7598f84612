"""``JobLifecycle``: the one owner of a job's Redis keys (``hgcore.jobs.keys``) and of every change a job
goes through, from its creation to its final artifacts. The API (``service.jobs``), the RQ tasks and the
worker class (``worker``), the reconciler and regression evaluation all read and write jobs through it.

::

    create      add_to(pipe, record, scene)         record, scene, queued steps, indexes (API, one MULTI)
    a step      start_chunk / start_merge           step running (attempt counted), job running
                report_progress                     a chunk's fraction; the job's progress published
                publish_round                       a noise-target round's preview partial and its block
                finish_chunk                        step done, samples and seconds counted
    the end     finalize                            artifacts, worker.log, scene.json, manifest → succeeded
                fail                                worker.log, manifest → failed
                cancel, close_unfinished_steps      → canceled (the API also stops the job's RQ steps)
                remove                              every key of the job (the API deletes its artifacts)

Every status change is one Lua script call (``transition``), so concurrent workers and the API cannot race,
and a final status never changes; a job's published progress never goes backwards. Records are typed
(``hgcore.jobs.record``); views are built from them (``hgcore.jobs.views``).
"""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path
from typing import Any

import redis
import redis.asyncio as aioredis

from hgcore.artifacts.keys import artifact_key, chunk_key, chunks_prefix, scene_key
from hgcore.jobs import manifest
from hgcore.jobs.keys import (
    JOBS_BY_STATE,
    JOBS_INDEX,
    RENDER_SECONDS_TOTAL,
    SAMPLES_TOTAL,
    events_channel,
    job_key,
    owner_index_key,
    scene_document_key,
    steps_key,
)
from hgcore.jobs.record import MERGE_STEP, JobRecord, JobSteps, StepName, StepRecord, decode_hash
from hgcore.jobs.status import ALLOWED_FROM, JobStatus
from hgcore.jobs.views import JobView, build_view
from hgcore.store.base import ArtifactNotFoundError, ArtifactStore

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
local last = tonumber(redis.call('HGET', KEYS[1], 'progress_published') or '') or -1
local progress = tonumber(ARGV[1])
if progress <= last then return 0 end
redis.call('HSET', KEYS[1], 'progress_published', ARGV[1])
redis.call('PUBLISH', ARGV[2], ARGV[3])
return 1
"""

# KEYS: job hash. ARGV: the running status, field, value, channel, payload (channel '': publish nothing).
# Sets one field of a running job (and publishes the payload), only while the job runs: a job deleted or
# canceled meanwhile is not recreated, nor changed, by a late worker.
_SET_WHILE_RUNNING_LUA = """
if redis.call('HGET', KEYS[1], 'status') ~= ARGV[1] then return 0 end
redis.call('HSET', KEYS[1], ARGV[2], ARGV[3])
if ARGV[4] ~= '' then redis.call('PUBLISH', ARGV[4], ARGV[5]) end
return 1
"""


class JobNotFoundError(KeyError):
    """No job with this id (or not visible to the caller)."""


class JobLifecycle:
    """A job's record, steps, scene, status, events and final artifacts, in Redis and the artifact store.

    ``aclient``: an asyncio client for the API's hot read path (``aview``)."""

    def __init__(self, client: redis.Redis, store: ArtifactStore, aclient: aioredis.Redis | None = None):
        self.client = client
        self.store = store
        self.aclient = aclient
        self._transition_script = client.register_script(_TRANSITION_LUA)
        self._publish_progress_script = client.register_script(_PUBLISH_PROGRESS_LUA)
        self._set_while_running_script = client.register_script(_SET_WHILE_RUNNING_LUA)

    # ---- creation and removal -------------------------------------------------------------------------

    @staticmethod
    def add_to(pipe: redis.client.Pipeline, record: JobRecord, scene: dict[str, Any]) -> None:
        """Queue, in ``pipe``'s transaction, the writes of a new job: its record, scene document, queued
        steps, index entries and status count (the caller adds its RQ job graph to the same MULTI)."""
        pipe.hset(job_key(record.id), mapping=record.to_hash())
        pipe.set(scene_document_key(record.id), json.dumps(scene, separators=(",", ":")))
        pipe.hset(steps_key(record.id), mapping=JobSteps.initial_hash(record.chunk_count))
        pipe.zadd(JOBS_INDEX, {record.id: record.created_at})
        pipe.zadd(owner_index_key(record.owner), {record.id: record.created_at})
        pipe.hincrby(JOBS_BY_STATE, record.status.value, 1)

    def remove(self, job_id: str) -> None:
        """Delete the job's keys and index entries, and uncount its status."""
        record = self.record(job_id)
        with self.client.pipeline() as pipe:
            pipe.delete(job_key(job_id), steps_key(job_id), scene_document_key(job_id))
            pipe.zrem(JOBS_INDEX, job_id)
            if record is not None:
                pipe.zrem(owner_index_key(record.owner), job_id)
                pipe.hincrby(JOBS_BY_STATE, record.status.value, -1)
            pipe.execute()

    # ---- reading --------------------------------------------------------------------------------------

    def record(self, job_id: str) -> JobRecord | None:
        """The job's record, or None when Redis has none (unknown, deleted, or lost with Redis)."""
        fields = decode_hash(self.client.hgetall(job_key(job_id)))
        return JobRecord.from_hash(fields) if fields else None

    def status(self, job_id: str) -> JobStatus | None:
        value = self.client.hget(job_key(job_id), JobRecord.hash_name("status"))
        return JobStatus(value.decode()) if value is not None else None

    def steps(self, job_id: str) -> JobSteps:
        """The bookkeeping of the job's steps (no chunks when the job is unknown)."""
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hget(job_key(job_id), JobRecord.hash_name("chunk_count"))
            pipe.hgetall(steps_key(job_id))
            chunk_count, fields = pipe.execute()
        return JobSteps.from_hash(decode_hash(fields), int(chunk_count or 0))

    def scene(self, job_id: str) -> dict[str, Any]:
        """The job's validated scene document: kept in Redis with the record (so a submission touches no
        disk), and copied to the store as ``scene.json`` with the final artifacts."""
        data = self.client.get(scene_document_key(job_id))
        if data is None:
            try:
                data = self.store.get_bytes(scene_key(job_id))
            except ArtifactNotFoundError:
                raise JobNotFoundError(job_id) from None
        return json.loads(data)

    @staticmethod
    def _view(record_hash: dict[bytes, bytes], steps_hash: dict[bytes, bytes]) -> JobView:
        record = JobRecord.from_hash(decode_hash(record_hash))
        return build_view(record, JobSteps.from_hash(decode_hash(steps_hash), record.chunk_count))

    def view(self, job_id: str) -> JobView | None:
        """The job's current view, or (when Redis lost it) the one in its manifest; None if unknown."""
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hgetall(job_key(job_id))
            pipe.hgetall(steps_key(job_id))
            record_hash, steps_hash = pipe.execute()
        if record_hash:
            return self._view(record_hash, steps_hash)
        return manifest.read_manifest_view(self.store, job_id)

    async def aview(self, job_id: str) -> JobView | None:
        """``view`` on the asyncio client (the API's most frequent request stays off the thread pool)."""
        if self.aclient is None:
            raise RuntimeError("aclient: JobLifecycle was built without an asyncio Redis client")
        async with self.aclient.pipeline(transaction=False) as pipe:
            pipe.hgetall(job_key(job_id))
            pipe.hgetall(steps_key(job_id))
            record_hash, steps_hash = await pipe.execute()
        if record_hash:
            return self._view(record_hash, steps_hash)
        return await asyncio.to_thread(manifest.read_manifest_view, self.store, job_id)

    def views(self, job_ids: list[str]) -> list[JobView]:
        """Views of several jobs in one round trip (jobs deleted meanwhile are left out)."""
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in job_ids:
                pipe.hgetall(job_key(job_id))
                pipe.hgetall(steps_key(job_id))
            replies = pipe.execute()
        return [self._view(r, s) for r, s in zip(replies[::2], replies[1::2], strict=True) if r]

    def _statuses(self, job_ids: list[str]) -> list[JobStatus | None]:
        with self.client.pipeline(transaction=False) as pipe:
            for job_id in job_ids:
                pipe.hget(job_key(job_id), JobRecord.hash_name("status"))
            return [JobStatus(s.decode()) if s is not None else None for s in pipe.execute()]

    def list_views(
        self, owner: str | None, status: JobStatus | None, offset: int, limit: int
    ) -> tuple[list[JobView], int]:
        """Jobs newest first, of one owner (None: all), optionally of one status; (page, total)."""
        index = JOBS_INDEX if owner is None else owner_index_key(owner)
        if status is None:
            total = int(self.client.zcard(index))
            ids = [i.decode() for i in self.client.zrevrange(index, offset, offset + limit - 1)]
            return self.views(ids), total
        # Filtering by status scans the owner's index; statuses live in the records.
        ids = [i.decode() for i in self.client.zrevrange(index, 0, -1)]
        matching = [i for i, s in zip(ids, self._statuses(ids), strict=True) if s == status]
        return self.views(matching[offset : offset + limit]), len(matching)

    def unfinished_job_ids(self) -> list[str]:
        """Ids of the jobs still queued or running, oldest first."""
        ids = [i.decode() for i in self.client.zrange(JOBS_INDEX, 0, -1)]
        unfinished = {JobStatus.QUEUED, JobStatus.RUNNING}
        return [i for i, status in zip(ids, self._statuses(ids), strict=True) if status in unfinished]

    def counts_by_state(self) -> dict[str, int]:
        counts = {k: int(v) for k, v in decode_hash(self.client.hgetall(JOBS_BY_STATE)).items()}
        return {s.value: counts.get(s.value, 0) for s in JobStatus}

    def render_totals(self) -> tuple[float, int]:
        """Seconds rendered and samples rendered by every step so far (the metrics' counters)."""
        seconds, samples = self.client.mget(RENDER_SECONDS_TOTAL, SAMPLES_TOTAL)
        return float(seconds or 0.0), int(samples or 0)

    # ---- transitions and events -----------------------------------------------------------------------

    def transition(self, job_id: str, new_status: JobStatus, **fields: Any) -> JobStatus | None:
        """Move the job to ``new_status`` if allowed, setting record ``fields``; returns the previous
        status, or None if not moved."""
        allowed = [s.value for s in ALLOWED_FROM[new_status]]
        pairs = [x for kv in JobRecord.encode_fields(**fields).items() for x in kv]
        previous = self._transition_script(
            keys=[job_key(job_id), JOBS_BY_STATE],
            args=[new_status.value, len(allowed), *allowed, *pairs],
        )
        if previous is None:
            return None
        self.publish(job_id, {"type": "status", "status": new_status.value})
        return JobStatus(previous.decode())

    def publish(self, job_id: str, event: dict[str, Any]) -> None:
        self.client.publish(events_channel(job_id), json.dumps(event))

    def _set_while_running(self, job_id: str, event: dict[str, Any] | None = None, **field: Any) -> bool:
        ((name, value),) = JobRecord.encode_fields(**field).items()
        channel, payload = (events_channel(job_id), json.dumps(event)) if event is not None else ("", "")
        written = self._set_while_running_script(
            keys=[job_key(job_id)], args=[JobStatus.RUNNING.value, name, value, channel, payload]
        )
        return bool(written)

    # ---- steps (written by the work horses) -----------------------------------------------------------

    def start_chunk(self, job_id: str, index: int, worker: str, pid: int, spp: int) -> int:
        """A work horse (process ``pid`` of ``worker``) began chunk ``index``; returns the attempt's
        number (1 for the first)."""
        return self._start_step(job_id, index, worker, pid, spp)

    def start_merge(self, job_id: str, worker: str, pid: int) -> int:
        """A work horse began the job's merge step; returns the attempt's number."""
        return self._start_step(job_id, MERGE_STEP, worker, pid, None)

    def _start_step(self, job_id: str, step: StepName, worker: str, pid: int, spp: int | None) -> int:
        now = time.time()
        fields = StepRecord.encode_step(
            step, status="running", progress=0.0, worker=worker, pid=pid, spp=spp, started_at=now
        )
        with self.client.pipeline() as pipe:
            pipe.hset(steps_key(job_id), mapping=fields)
            pipe.hincrby(steps_key(job_id), StepRecord.field_name(step, "attempts"), 1)
            _, attempt = pipe.execute()
        self.transition(job_id, JobStatus.RUNNING, started_at=now)
        return int(attempt)

    def report_progress(self, job_id: str, index: int, fraction: float) -> None:
        """Store one chunk's progress and publish the job's aggregated progress."""
        fraction = min(1.0, max(0.0, fraction))
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hset(steps_key(job_id), mapping=StepRecord.encode_step(index, progress=fraction))
            pipe.hgetall(job_key(job_id))
            pipe.hgetall(steps_key(job_id))
            _, record_hash, steps_hash = pipe.execute()
        if not record_hash:
            return
        view = self._view(record_hash, steps_hash)
        event = {
            "type": "progress",
            "progress": view.progress,
            "chunks_done": view.chunks_done,
            "chunks_total": view.chunks_total,
            "eta_s": view.eta_s,
        }
        self._publish_progress_script(
            keys=[job_key(job_id)], args=[repr(view.progress), events_channel(job_id), json.dumps(event)]
        )

    def publish_round(self, job_id: str, partial_path: Path, block: dict[str, Any]) -> bool:
        """A running noise-target job finished a round: store the image of the rounds so far as chunk 0's
        partial (``jobs/<id>/chunks/0.npz``; the viewer merges chunk partials into a running job's image),
        record the block of the rounds so far (``hgcore.noise_target.summary_block``, ``stop_reason``
        null) for the job view and publish a ``round`` message on the job's channel (an event stream
        answers any message other than ``progress`` with the re-read view). False (nothing recorded)
        unless the job is running."""
        self.store.put_file(chunk_key(job_id, 0), partial_path)
        event = {"type": "round", "noise_target": block}
        return self._set_while_running(job_id, event, noise_target_outcome=block)

    def finish_chunk(self, job_id: str, index: int, samples: int, seconds: float) -> None:
        """Chunk ``index`` completed: count the completion (tests check it is counted once)."""
        self._finish_step(job_id, index, samples, seconds)
        self.report_progress(job_id, index, 1.0)

    def _finish_step(self, job_id: str, step: StepName, samples: int, seconds: float) -> None:
        fields = StepRecord.encode_step(
            step, status="done", progress=1.0, samples=samples, seconds=seconds, finished_at=time.time()
        )
        with self.client.pipeline() as pipe:
            pipe.hset(steps_key(job_id), mapping=fields)
            pipe.hincrby(steps_key(job_id), StepRecord.field_name(step, "completions"), 1)
            pipe.incrbyfloat(RENDER_SECONDS_TOTAL, seconds)
            pipe.incrby(SAMPLES_TOTAL, samples)
            pipe.execute()

    def mark_chunk_canceled(self, job_id: str, index: int) -> None:
        """A chunk stopped because its job was canceled or deleted."""
        self.client.hset(steps_key(job_id), mapping=StepRecord.encode_step(index, status="canceled"))

    # ---- the end: succeeded, failed, canceled ---------------------------------------------------------

    def finalize(
        self, job_id: str, out_dir: Path, summary: dict[str, Any], merge_started_s: float
    ) -> dict[str, Any]:
        """Upload the job's artifacts written to ``out_dir`` (``summary``: its summary.json), then its log,
        scene and manifest, and mark it succeeded (the merge step, begun at ``merge_started_s`` on the
        monotonic clock, is booked done). A noise-target job's achieved error goes into its record."""
        scene_document = self.scene(job_id)
        if "noise_target" in summary:
            self._set_while_running(job_id, noise_target_outcome=summary["noise_target"])
        for path in sorted(out_dir.rglob("*")):
            if path.is_file():
                self.store.put_file(artifact_key(job_id, path.relative_to(out_dir).as_posix()), path)
        if "noise_target" in summary:
            # The rounds' preview (``publish_round``) is superseded by image.exr: a target job's artifacts
            # and manifest are what they were without previews.
            self.store.delete_prefix(chunks_prefix(job_id))
        merge_s = time.monotonic() - merge_started_s
        self._finish_step(job_id, MERGE_STEP, samples=0, seconds=merge_s)
        view = self._require_view(job_id)
        manifest.write_worker_log(self.store, view)
        self.store.put_bytes(scene_key(job_id), json.dumps(scene_document, indent=1).encode())  # provenance
        # The manifest is complete before the status says succeeded, so a client never misses or races it.
        final = {"status": JobStatus.SUCCEEDED.value, "progress": 1.0, "eta_s": None}
        self._end(job_id, JobStatus.SUCCEEDED, final)
        return {"summary": summary, "merge_s": merge_s}

    def fail(self, job_id: str, error: str) -> None:
        """Fail the job with ``error`` (one line naming the step), its log and manifest first, unless it
        already ended (it may have been canceled or deleted meanwhile)."""
        if self.status(job_id) in {JobStatus.QUEUED, JobStatus.RUNNING}:
            manifest.write_worker_log(self.store, self._require_view(job_id), error)
            final = {"status": JobStatus.FAILED.value, "error": error, "eta_s": None}
            self._end(job_id, JobStatus.FAILED, final, error=error)

    def _end(self, job_id: str, status: JobStatus, final: dict[str, Any], **fields: Any) -> None:
        """Write the manifest with the ``final`` view fields, then move the job to ``status``; when a
        cancel won the race, rewrite the manifest as the job now is."""
        finished_at = time.time()
        view = self._require_view(job_id)
        artifacts = manifest.artifact_digests(self.store, job_id)
        total_s = finished_at - view.timings.created_at
        manifest.write_manifest(self.store, view, artifacts, final, finished_at=finished_at, total_s=total_s)
        if self.transition(job_id, status, finished_at=finished_at, **fields) is None:
            manifest.write_manifest(self.store, self._require_view(job_id), artifacts, {})

    def _require_view(self, job_id: str) -> JobView:
        view = self.view(job_id)
        if view is None:
            raise JobNotFoundError(job_id)
        return view

    def cancel(self, job_id: str) -> bool:
        """Mark the job canceled; False when it had already ended (or does not exist). Its steps still
        read as they were: stop them, then ``close_unfinished_steps``."""
        return self.transition(job_id, JobStatus.CANCELED, finished_at=time.time()) is not None

    def close_unfinished_steps(self, job_id: str) -> None:
        """Steps of a canceled job that had not finished read ``canceled``, not ``running`` or ``queued``
        forever (their RQ jobs were dropped or stopped)."""
        steps = self.steps(job_id)
        named = [*enumerate(steps.chunks), *([(MERGE_STEP, steps.merge)] if steps.merge is not None else [])]
        unfinished: dict[str, str] = {}
        for step, record in named:
            if record.status in {"queued", "running"}:
                unfinished |= StepRecord.encode_step(step, status="canceled")
        if unfinished:
            self.client.hset(steps_key(job_id), mapping=unfinished)
