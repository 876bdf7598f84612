"""Fixtures of the viewer tests: tiny rendered jobs of a plane under a cylinder light (``tests.support
.scenes.cylinder_scene``) with their EXRs read back with OpenImageIO, and a page of headless Chromium on the
module's ``live_service``, which runs a worker for every viewer test module."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.support.browser import token_page
from tests.support.live_service import LiveService, RenderedJob
from tests.support.scenes import cylinder_scene


@pytest.fixture(scope="module", autouse=True)
def _worker(live_service: LiveService) -> None:
    """The module's service renders: what a test or a page submits runs (one worker)."""
    live_service.ensure_worker()


@pytest.fixture(scope="module")
def cylinder_job(live_service: LiveService) -> RenderedJob:
    return live_service.render_image(cylinder_scene(), "cylinder")


@pytest.fixture(scope="module")
def cylinder_job_reseeded(live_service: LiveService) -> RenderedJob:
    """The same scene with another seed: a different noise pattern to compare against."""
    return live_service.render_image(cylinder_scene(seed=7), "cylinder seed 7")


@pytest.fixture(scope="module")
def diagonal_cylinder_job(live_service: LiveService) -> RenderedJob:
    """The cylinder along (x̂ + ẑ)/√2: ℓ₁ at +45° in the image (up and to the right)."""
    return live_service.render_image(cylinder_scene(axis_end_m=(0.3, 0.3)), "diagonal cylinder")


@pytest.fixture
def page(chromium: Any, live_service: LiveService) -> Iterator[Any]:
    """A 1280×800 page with the admin token in localStorage; fails the test on page errors."""
    with token_page(chromium, live_service.token, 1280, 800) as page:
        yield page
