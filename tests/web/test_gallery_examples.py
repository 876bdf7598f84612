"""The viewer's gallery strip: one-click examples with thumbnails, opened in their most telling view."""

from __future__ import annotations

from typing import Any

import pytest

from schemas.gallery import GALLERY
from tests.support.browser import (
    MAX_ELLIPSE_COVERAGE,
    assert_ellipses_inside_their_cells,
    overlay_coverage,
    screenshot,
)
from tests.support.live_service import LiveService

pytestmark = pytest.mark.browser


def test_examples_list_the_gallery_first_with_figure_view_and_thumbnail(live_service: LiveService) -> None:
    listed = live_service.get("/v1/examples").json()
    gallery = listed[: len(GALLERY)]
    assert [e["name"] for e in gallery] == [f"{entry.name}.json" for entry in GALLERY]
    assert all(e["figure"] and e["view"] in {"image", "ellipses"} for e in gallery)
    assert all(e["figure"] is None for e in listed[len(GALLERY) :])
    cylinder = next(e for e in gallery if e["name"] == "fig7_thin_film_cylinder_light.json")
    assert cylinder["view"] == "ellipses"
    thumbnail = live_service.get(cylinder["thumbnail"])
    assert thumbnail.headers["content-type"] == "image/png" and thumbnail.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert live_service.get("/v1/examples/cornell_box/thumbnail.png").status_code == 404


def test_one_click_renders_the_cylinder_scene_and_opens_it_with_ellipses(
    page: Any, live_service: LiveService
) -> None:
    page.goto(f"{live_service.base_url}/#/jobs")
    button = '#gallery-examples button[data-example="fig7_thin_film_cylinder_light.json"]'
    page.wait_for_selector(button)
    # Every thumbnail loaded (through the authenticated API, as an object URL).
    images = "[...document.querySelectorAll('#gallery-examples img')]"
    page.wait_for_function(
        f"() => {images}.length === {len(GALLERY)} && {images}.every((i) => i.complete && i.naturalWidth > 0)"
    )
    screenshot(page, "gallery_strip")
    # Small overrides keep the test quick; the click submits at once, named after the scene.
    page.fill("#override-width", "32")
    page.fill("#override-height", "32")
    page.fill("#override-spp", "4")
    page.click(button)
    page.wait_for_function(
        "() => document.querySelector('#submit-status').textContent.startsWith('submitted')"
    )
    job_id = page.inner_text("#submit-status").split()[-1]
    final = live_service.wait_final(job_id)
    assert final["status"] == "succeeded" and final["name"] == "fig7_thin_film_cylinder_light"
    page.wait_for_selector(f'tr[data-job-id="{job_id}"][data-status="succeeded"]')
    page.goto(f"{live_service.base_url}/#/view/{job_id}")
    page.wait_for_function("() => Number(document.querySelector('#image-canvas').dataset.drawn) >= 1")
    assert page.is_checked("#show-ellipses")
    page.wait_for_function("() => document.querySelectorAll('#ellipse-overlay ellipse').length > 0")
    # Issue 29: the ellipses stay inside their grid cells (auto scale) and the image, and leave most of
    # the picture visible.
    assert_ellipses_inside_their_cells(page)
    assert overlay_coverage(page) <= MAX_ELLIPSE_COVERAGE
    screenshot(page, "gallery_cylinder_opened")
