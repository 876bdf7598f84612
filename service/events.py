"""Server-Sent Events of one job: a ``status`` event with the full job view first, then ``progress``
events as chunks advance and a ``status`` event at every status change, until a final status.

Workers publish to the Redis channel ``hgrender:events:<id>`` (``JobLifecycle.publish``). The stream
subscribes *before* reading the first snapshot, so no change between the two is missed, and re-reads
the job every ``resync_s`` so that a lost message (e.g. Redis restarted) cannot stall a client.
"""

from __future__ import annotations

import json
import time
from collections.abc import AsyncIterator

import redis.asyncio as aioredis
from starlette.requests import Request

from hgcore.jobs.keys import events_channel
from hgcore.jobs.status import TERMINAL_STATUSES
from hgcore.jobs.views import JobView
from service.jobs import JobService


async def job_events(
    request: Request, client: aioredis.Redis, jobs: JobService, job_id: str, resync_s: float = 5.0
) -> AsyncIterator[dict[str, str]]:
    """Yield sse-starlette event dicts (``event``, ``data``) for ``job_id``."""
    pubsub = client.pubsub()
    await pubsub.subscribe(events_channel(job_id))
    try:
        view = await jobs.aget(job_id)
        if view is None:
            return
        yield _status_event(view)
        last_sync_s = time.monotonic()
        while view.status not in TERMINAL_STATUSES:
            if await request.is_disconnected():
                return
            message = await pubsub.get_message(ignore_subscribe_messages=True, timeout=1.0)
            event = json.loads(message["data"]) if message is not None else None
            if event is not None and event.get("type") == "progress":
                yield {"event": "progress", "data": json.dumps(event)}
                continue
            if event is None and time.monotonic() - last_sync_s < resync_s:
                continue
            last_sync_s = time.monotonic()
            latest = await jobs.aget(job_id)
            if latest is None:  # deleted
                return
            if latest.status != view.status or event is not None:
                yield _status_event(latest)
            view = latest
    finally:
        await pubsub.unsubscribe()
        await pubsub.aclose()


def _status_event(view: JobView) -> dict[str, str]:
    return {"event": "status", "data": view.model_dump_json()}
