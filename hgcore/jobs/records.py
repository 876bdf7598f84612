"""``JobRecords``: a job's record in Redis, its atomic status transitions and events, and the chunk
bookkeeping that workers write while they render (key layout: ``hgcore.jobs.keys``).

Every transition is one Lua script call, so concurrent workers and the API cannot race; a job's published
progress never goes backwards. Workers use this class directly; the API's ``service.jobs.JobService``
adds creation, listing, cancel and delete on top of it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from typing import Any

import redis

from hgcore.artifacts.keys import manifest_key, scene_key
from hgcore.jobs.keys import (
    JOBS_BY_STATE,
    RENDER_SECONDS_TOTAL,
    SAMPLES_TOTAL,
    chunks_key,
    events_channel,
    job_key,
    scene_document_key,
)
from hgcore.jobs.status import ALLOWED_FROM, JobStatus
from hgcore.jobs.views import JobView, build_view
from hgcore.settings import Settings
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
local last = tonumber(redis.call('HGET', KEYS[1], 'progress_published') or '-1')
local progress = tonumber(ARGV[1])
if progress <= last then return 0 end
redis.call('HSET', KEYS[1], 'progress_published', ARGV[1])
redis.call('PUBLISH', ARGV[2], ARGV[3])
return 1
"""

# KEYS: job hash. ARGV: noise-target block (JSON), channel, payload, the running status. Stores a
# running noise-target job's block of the rounds so far and publishes it, only while the job runs: a job
# deleted or canceled meanwhile is not recreated by a late round.
_NOISE_TARGET_ROUND_LUA = """
if redis.call('HGET', KEYS[1], 'status') ~= ARGV[4] then return 0 end
redis.call('HSET', KEYS[1], 'noise_target', ARGV[1])
redis.call('PUBLISH', ARGV[2], ARGV[3])
return 1
"""


class JobNotFoundError(KeyError):
    """No job with this id (or not visible to the caller)."""


def decode_hash(mapping: Mapping[bytes, bytes]) -> dict[str, str]:
    """A Redis hash reply as ``str`` keys and values."""
    return {k.decode(): v.decode() for k, v in mapping.items()}


class JobRecords:
    """A job's record, status, events, scene document and chunk bookkeeping, for the API and workers."""

    def __init__(self, client: redis.Redis, store: ArtifactStore, settings: Settings) -> None:
        self.client = client
        self.store = store
        self.settings = settings
        self._transition_script = client.register_script(_TRANSITION_LUA)
        self._publish_progress_script = client.register_script(_PUBLISH_PROGRESS_LUA)
        self._noise_target_round_script = client.register_script(_NOISE_TARGET_ROUND_LUA)

    # ---- reading --------------------------------------------------------------------------------------

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

    def get(self, job_id: str) -> JobView | None:
        """The job's current view, or (when Redis lost it) the one in its manifest; None if unknown."""
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hgetall(job_key(job_id))
            pipe.hgetall(chunks_key(job_id))
            record, chunk_fields = pipe.execute()
        if record:
            return build_view(decode_hash(record), decode_hash(chunk_fields))
        return self._view_from_manifest(job_id)

    def _view_from_manifest(self, job_id: str) -> JobView | None:
        if not job_id.isalnum():
            return None
        try:
            manifest = json.loads(self.store.get_bytes(manifest_key(job_id)))
        except (ArtifactNotFoundError, ValueError):
            return None
        return JobView.model_validate(manifest["job"])

    def record(self, job_id: str) -> dict[str, str]:
        return decode_hash(self.client.hgetall(job_key(job_id)))

    def status(self, job_id: str) -> JobStatus | None:
        value = self.client.hget(job_key(job_id), "status")
        return JobStatus(value.decode()) if value is not None else None

    # ---- transitions and events -----------------------------------------------------------------------

    def transition(self, job_id: str, new_status: JobStatus, **fields: str) -> JobStatus | None:
        """Move the job to ``new_status`` if allowed; returns the previous status, or None if not moved."""
        allowed = [s.value for s in ALLOWED_FROM[new_status]]
        pairs = [str(x) for kv in fields.items() for x in kv]
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

    # ---- chunk bookkeeping (written by workers) -------------------------------------------------------

    def chunk_started(
        self, job_id: str, index: int | str, worker: str, pid: int, spp: int | None = None
    ) -> None:
        """A work horse (process ``pid`` of ``worker``) began chunk ``index`` (or ``merge``)."""
        fields = {
            "status": "running",
            "progress": "0",
            "worker": worker,
            "pid": str(pid),
            "spp": "" if spp is None else str(spp),
            "started_at": repr(time.time()),
        }
        with self.client.pipeline() as pipe:
            self._set_chunk_fields(pipe, job_id, index, fields, count="attempts")
            pipe.execute()
        self.transition(job_id, JobStatus.RUNNING, started_at=repr(time.time()))

    @staticmethod
    def _set_chunk_fields(
        pipe: redis.client.Pipeline, job_id: str, index: int | str, fields: dict[str, str], count: str
    ) -> None:
        """Queue ``<index>.<field>`` writes for one chunk and one increment of its ``count`` field."""
        pipe.hset(chunks_key(job_id), mapping={f"{index}.{name}": value for name, value in fields.items()})
        pipe.hincrby(chunks_key(job_id), f"{index}.{count}", 1)

    def chunk_progress(self, job_id: str, index: int, fraction: float) -> None:
        """Store one chunk's progress and publish the job's aggregated progress."""
        fraction = min(1.0, max(0.0, fraction))
        with self.client.pipeline(transaction=False) as pipe:
            pipe.hset(chunks_key(job_id), f"{index}.progress", repr(fraction))
            pipe.hgetall(job_key(job_id))
            pipe.hgetall(chunks_key(job_id))
            _, record, chunk_fields = pipe.execute()
        if record:
            view = build_view(decode_hash(record), decode_hash(chunk_fields))
            event = {
                "type": "progress",
                "progress": view.progress,
                "chunks_done": view.chunks_done,
                "chunks_total": view.chunks_total,
                "eta_s": view.eta_s,
            }
            self._publish_progress_script(
                keys=[job_key(job_id)],
                args=[repr(view.progress), events_channel(job_id), json.dumps(event)],
            )

    def noise_target_round(self, job_id: str, block: dict[str, Any]) -> bool:
        """A running noise-target job finished a round (its preview is stored): record the block of the
        rounds so far (``hgcore.noise_target.summary_block``, ``stop_reason`` null) for the job view and
        publish a ``round`` message on the job's channel (an event stream answers any message other
        than ``progress`` with the re-read view: a ``status`` event carrying the new block). False
        (nothing written) unless the job is running."""
        payload = json.dumps(block)
        event = json.dumps({"type": "round", "noise_target": block})
        written = self._noise_target_round_script(
            keys=[job_key(job_id)], args=[payload, events_channel(job_id), event, JobStatus.RUNNING.value]
        )
        return bool(written)

    def chunk_finished(self, job_id: str, index: int | str, samples: int, seconds: float) -> None:
        """A chunk (or ``merge``) completed: count the completion (tests check it is counted once)."""
        fields = {
            "status": "done",
            "progress": "1",
            "samples": str(samples),
            "seconds": repr(seconds),
            "finished_at": repr(time.time()),
        }
        with self.client.pipeline() as pipe:
            self._set_chunk_fields(pipe, job_id, index, fields, count="completions")
            pipe.incrbyfloat(RENDER_SECONDS_TOTAL, seconds)
            pipe.incrby(SAMPLES_TOTAL, samples)
            pipe.execute()
        if index != "merge":
            self.chunk_progress(job_id, int(index), 1.0)

    def chunk_fields(self, job_id: str) -> dict[str, str]:
        """The raw ``<i>.<field>`` / ``merge.<field>`` bookkeeping of a job's chunks."""
        return decode_hash(self.client.hgetall(chunks_key(job_id)))

    def chunk_completions(self, job_id: str) -> dict[str, int]:
        """How many times each chunk (and ``merge``) ran to completion."""
        fields = self.chunk_fields(job_id)
        return {
            k.removesuffix(".completions"): int(v) for k, v in fields.items() if k.endswith(".completions")
        }

    def set_chunk_status(self, job_id: str, index: int | str, status: str) -> None:
        self.client.hset(chunks_key(job_id), f"{index}.status", status)
