"""Redis clients for the API, the workers and the scheduler.

redis-py reads its own version from the package metadata for every new connection (``CLIENT SETINFO``);
that costs ~4 ms in a freshly forked work horse, on every job. The clients made here name the version
once, at import.
"""

from __future__ import annotations

from typing import Any

import redis
import redis.asyncio as aioredis
from redis.driver_info import DriverInfo


def _driver_info() -> DriverInfo:
    return DriverInfo(lib_version=redis.__version__)


def redis_client(url: str, **options: Any) -> redis.Redis:
    """A client of the Redis server at ``url`` (``options``: redis-py's connection options)."""
    return redis.Redis.from_url(url, driver_info=_driver_info(), **options)


def async_redis_client(url: str, **options: Any) -> aioredis.Redis:
    """An asyncio client of the Redis server at ``url``."""
    return aioredis.Redis.from_url(url, driver_info=_driver_info(), **options)
