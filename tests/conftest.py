"""Shared fixtures: a private Redis server for the session (never the machine's 127.0.0.1:6379)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from service.redis_server import RedisServer


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RedisServer]:
    """A ``redis-server`` on a free loopback port with AOF on, data in a temporary directory."""
    server = RedisServer(tmp_path_factory.mktemp("redis")).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="session")
def redis_url(redis_server: RedisServer) -> str:
    return redis_server.url
