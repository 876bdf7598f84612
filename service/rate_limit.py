"""Per-token request counting for the API's rate limit: a fixed one-minute window per token, shared by
every API process through one Redis counter per token and window (``hgrender:ratelimit:<token id>:<window>``).

Why counts are written in batches: the private Redis fsyncs its append-only file before it answers any
write (``appendfsync always``, ``service/redis_server.py``), about 8 ms on these disks, so an ``INCR`` per
request made every authenticated request wait for a disk flush (``GET /v1/jobs/{id}`` went from ≈440 to
≈190 requests/s). The request path therefore only *reads* the shared counter (in the same round trip as
the token record) and adds what this process has counted but not yet written; a background task adds the
process's counts to Redis with ``INCRBY`` every ``flush_interval_s`` (one write per active token, not per
request). Within one process the limit is exact. Across P processes a token can exceed it by at most what
the other P−1 processes count in one flush interval (limit/minute × P × 0.1 s ⁄ 60 s ≈ 0.2 % of the limit at
the default interval) — the usual trade of a distributed fixed-window limiter.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import Counter

import redis.asyncio as aioredis

WINDOW_S = 60
COUNTER_TTL_S = 2 * WINDOW_S  # a window's counter outlives the window; Redis drops it after


def counter_key(token_id: str, window: int) -> str:
    """The Redis counter of ``token_id``'s requests in minute ``window`` (Unix time // 60)."""
    return f"hgrender:ratelimit:{token_id}:{window}"


def current_window(now_s: float) -> int:
    return int(now_s // WINDOW_S)


def retry_after_s(window: int, now_s: float) -> int:
    """Whole seconds until the next window opens (at least 1)."""
    return max(1, int((window + 1) * WINDOW_S - now_s) + 1)


class RequestCounter:
    """This API process's not-yet-written request counts, and the task that writes them to Redis.

    ``count(key, shared)`` is called with the shared counter's value as just read from Redis and returns
    the token's count in the window including this request; ``flush()`` moves the pending counts to Redis.
    Counts being written are kept apart (``in_flight``) until Redis acknowledges them, so a read that
    races a flush never sees a request neither in Redis nor here.
    """

    def __init__(self, aclient: aioredis.Redis, flush_interval_s: float = 0.1) -> None:
        self.aclient = aclient
        self.flush_interval_s = flush_interval_s
        self.pending: Counter[str] = Counter()
        self.in_flight: Counter[str] = Counter()
        self._task: asyncio.Task[None] | None = None

    def count(self, key: str, shared: int) -> int:
        self.pending[key] += 1
        self._ensure_flushing()
        return shared + self.in_flight[key] + self.pending[key]

    async def flush(self) -> None:
        """Add the pending counts to their Redis counters (one pipeline, ``INCRBY`` + ``EXPIRE`` each)."""
        if not self.pending:
            return
        batch, self.pending = self.pending, Counter()
        self.in_flight.update(batch)
        try:
            async with self.aclient.pipeline(transaction=False) as pipe:
                for key, requests in batch.items():
                    pipe.incrby(key, requests)
                    pipe.expire(key, COUNTER_TTL_S)
                await pipe.execute()
        except Exception:
            self.pending.update(batch)  # Redis is away: keep counting here, write them next time
            raise
        finally:
            self.in_flight.subtract(batch)
            self.in_flight = +self.in_flight  # drop zero entries

    async def aclose(self) -> None:
        """Stop the background task and write what is pending (called at API shutdown)."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        with contextlib.suppress(Exception):
            await self.flush()

    def _ensure_flushing(self) -> None:
        # Started by the first counted request, on the event loop that serves requests.
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._flush_periodically())

    async def _flush_periodically(self) -> None:
        while True:
            await asyncio.sleep(self.flush_interval_s)
            with contextlib.suppress(Exception):  # a Redis outage: the counts wait in ``pending``
                await self.flush()
