"""Shared fixtures (``tests/README.md``): a private Redis server for the session (never the machine's
127.0.0.1:6379), the live service each test module runs against, and one headless Chromium for every
browser test (Playwright's sync API allows one instance per session). Helpers live in ``tests/support``."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from hgcore.settings import Settings
from service.redis_server import RedisServer
from tests.support.live_service import LiveService, running_service
from worker.mitsuba_setup import configure_mitsuba


def pytest_configure(config: pytest.Config) -> None:
    """The test session is one process with one ``Settings`` (its environment): like every entry point,
    it configures Mitsuba's variant and thread count before any test module imports the renderer."""
    settings = Settings()
    configure_mitsuba(settings.variant, settings.render_threads)


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


@pytest.fixture(scope="module")
def live_service(redis_url: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveService]:
    """The API (uvicorn in a thread, auth on) over the session's Redis, flushed for each module, with a
    fresh data dir and admin token; tests start the workers they need (``start_worker``,
    ``ensure_worker``; ``render`` does). Its workers are stopped when the module ends."""
    with running_service(redis_url, tmp_path_factory.mktemp("service-data")) as service:
        yield service


CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture(scope="session")
def chromium() -> Iterator[Any]:
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is absent (install it with `make system-packages`)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()
