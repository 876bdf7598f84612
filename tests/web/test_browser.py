"""The viewer in headless Chromium against a live ``hgrender serve``: canvas pixels against the server's
display transform, exposure, the wavelength slider, coherence ellipses of a cylinder light, the pixel
inspector, live progress of a running job, the compare view, keyboard access and a narrow viewport.

Screenshots go to ``test-artifacts/``. Tolerances: the canvas is written from the same float32 data with
the same formulas in double precision (JS) as ``hgcore.imaging`` (NumPy), so 8-bit values agree except
where a value lands within rounding of a quantisation boundary: ±1 level.
"""

from __future__ import annotations

import io
import itertools
import re
import time
from typing import Any

import numpy as np
import pytest
from PIL import Image

from hgcore.imaging import auto_exposure_ev, display_rgb8
from tests.support.browser import canvas_rgb, drawn_count, redrawn, screenshot, viridis8
from tests.support.live_service import LiveService, RenderedJob
from tests.support.scenes import CYLINDER_SIZE_PX, cylinder_scene

pytestmark = pytest.mark.browser


def open_viewer(page: Any, live_service: LiveService, job_id: str) -> None:
    page.goto(f"{live_service.base_url}/#/view/{job_id}")
    page.wait_for_function("() => Number(document.querySelector('#image-canvas').dataset.drawn) >= 1")


def test_canvas_matches_server_display_and_exposure(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_viewer(page, live_service, cylinder_job.job_id)
    # The viewer opens at the automatic exposure (99th luminance percentile → white), not rounded: the
    # service's value from the bands equals the RGB luminance rule to float rounding.
    ev = float(page.get_attribute("#image-canvas", "data-ev"))
    assert ev == live_service.get(f"/v1/jobs/{cylinder_job.job_id}/layers").json()["exposure_ev"]
    assert ev == pytest.approx(auto_exposure_ev(cylinder_job.exr.rgb), abs=1e-3)
    assert page.input_value("#ev-value") == f"{ev:.2f}"
    shown = canvas_rgb(page)
    png = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/display.png", ev=ev, tonemap="clamp").content
    server = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int64)
    assert shown.shape == (CYLINDER_SIZE_PX, CYLINDER_SIZE_PX, 3)
    assert np.abs(shown - server).max() <= 1
    screenshot(page, "viewer_srgb")

    # +2 EV: every linear value ×4; the canvas follows display_rgb8(rgb, ev + 2) and brightens.
    brighter_ev = round(ev + 2.0, 1)
    count = drawn_count(page)
    page.fill("#ev-slider", str(brighter_ev))
    redrawn(page, count)
    brighter = canvas_rgb(page)
    expected = display_rgb8(cylinder_job.exr.rgb, brighter_ev, "clamp").astype(np.int64)
    assert np.abs(brighter - expected).max() <= 1
    assert np.abs(brighter - shown).max() > 10
    count = drawn_count(page)
    page.select_option("#tonemap", "aces")
    redrawn(page, count)
    expected = display_rgb8(cylinder_job.exr.rgb, brighter_ev, "aces").astype(np.int64)
    assert np.abs(canvas_rgb(page) - expected).max() <= 1
    assert page.input_value("#ev-value") == f"{brighter_ev:.2f}"


def test_wavelength_slider_switches_bands(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_viewer(page, live_service, cylinder_job.job_id)
    catalogue = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/layers").json()
    layers = {layer["name"]: layer for layer in catalogue["layers"]}
    bands = cylinder_job.exr.band_names()
    count = drawn_count(page)
    page.select_option("#display-mode", "band")
    redrawn(page, count)
    seen = []
    for index in (1, 5):
        count = drawn_count(page)
        page.fill("#band-slider", str(index))
        redrawn(page, count)
        info = layers[bands[index]]
        # The band's values mapped linearly over its [p01, p99] onto viridis.
        t = (cylinder_job.exr.channels[bands[index]].astype(np.float64) - info["p01"]) / (
            info["p99"] - info["p01"]
        )
        shown = canvas_rgb(page)
        assert np.abs(shown - viridis8(t)).max() <= 1, bands[index]
        assert page.inner_text("#band-label") == f"{info['wavelength_nm']:.1f} nm"
        seen.append(shown)
        screenshot(page, f"viewer_band_{index}")
    assert np.abs(seen[0] - seen[1]).max() > 10  # two different bands, two different pictures


def test_diagnostic_layer_uses_covered_pixels_and_legend(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_viewer(page, live_service, cylinder_job.job_id)
    count = drawn_count(page)
    page.select_option("#display-mode", "coherence.l1_um")
    redrawn(page, count)
    info = next(
        layer
        for layer in live_service.get(f"/v1/jobs/{cylinder_job.job_id}/layers").json()["layers"]
        if layer["name"] == "coherence.l1_um"
    )
    exr = cylinder_job.exr.channels
    covered = exr["coherence.weight"] > 0
    expected = viridis8((exr["coherence.l1_um"] - info["p01"]) / (info["p99"] - info["p01"]))
    expected[~covered] = 40  # uncovered pixels: dark grey
    assert np.abs(canvas_rgb(page) - expected).max() <= 1
    assert "µm" in page.inner_text("#legend")
    screenshot(page, "viewer_l1")


def test_ellipses_are_vertical_for_a_cylinder_light(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_viewer(page, live_service, cylinder_job.job_id)
    page.fill("#ellipse-spacing", "6")
    page.dispatch_event("#ellipse-spacing", "change")
    page.check("#show-ellipses")  # off in a job's first view (issue 29): one click (or C) away
    page.wait_for_function("() => document.querySelectorAll('#ellipse-overlay ellipse').length > 0")
    shapes = page.evaluate(
        """() => [...document.querySelectorAll('#ellipse-overlay ellipse')].map((e) => {
            const box = e.getBoundingClientRect();
            return {x: Number(e.dataset.x), y: Number(e.dataset.y), angle: Number(e.dataset.angle),
                    rx: Number(e.getAttribute('rx')), ry: Number(e.getAttribute('ry')),
                    width: box.width, height: box.height, transform: e.getAttribute('transform')};
        })"""
    )
    grid = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/ellipses", spacing=6).json()["ellipses"]
    assert len(shapes) == len(grid) >= 8
    angle = cylinder_job.exr.channels["coherence.angle"]
    for shape in shapes:
        assert shape["angle"] == pytest.approx(float(angle[shape["y"], shape["x"]]), abs=1e-7)
        assert shape["rx"] > shape["ry"]  # the ℓ₁ semi-axis is the longer one
        # Drawn on screen: taller than wide (ℓ₁ vertical), the rotation is −angle in SVG's y-down frame.
        assert shape["height"] > 1.5 * shape["width"]
        assert shape["transform"].startswith(f"rotate({-shape['angle'] * 180 / np.pi}")
    page.hover("#ellipse-overlay ellipse >> nth=0")
    assert "ℓ₁" in page.inner_text("#ellipse-info")
    screenshot(page, "viewer_ellipses")


def test_ellipses_are_drawn_with_the_angle_convention(
    page: Any, live_service: LiveService, diagonal_cylinder_job: RenderedJob
) -> None:
    """`angle` is counter-clockwise from +x with image +y up: ℓ₁ at +45° runs up and to the right."""
    open_viewer(page, live_service, diagonal_cylinder_job.job_id)
    page.check("#show-ellipses")
    page.wait_for_function("() => document.querySelectorAll('#ellipse-overlay ellipse').length > 0")
    directions = page.evaluate(
        """() => [...document.querySelectorAll('#ellipse-overlay ellipse')].map((e) => {
            // End points of the major (rx) axis, mapped to screen pixels by the element's full transform.
            const m = e.getScreenCTM();
            const cx = Number(e.getAttribute('cx')), cy = Number(e.getAttribute('cy'));
            const rx = Number(e.getAttribute('rx'));
            const a = new DOMPoint(cx - rx, cy).matrixTransform(m);
            const b = new DOMPoint(cx + rx, cy).matrixTransform(m);
            return [b.x - a.x, b.y - a.y, Number(e.dataset.angle)];
        })"""
    )
    assert len(directions) >= 4
    for dx, dy, angle in directions:
        # Screen y grows downwards: the drawn axis must be parallel to (cos θ, −sin θ).
        cross = dx * -np.sin(angle) - dy * np.cos(angle)
        assert abs(cross) < 1e-3 * np.hypot(dx, dy)
        assert dx * dy < 0  # up and to the right (or down and to the left): the +45° diagonal
    screenshot(page, "viewer_ellipses_diagonal")


def test_inspector_spectrum_equals_the_exr(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_viewer(page, live_service, cylinder_job.job_id)
    exr = cylinder_job.exr
    covered = np.argwhere(exr.channels["coherence.weight"] > 0)
    y, x = (int(v) for v in covered[len(covered) // 3])
    box = page.locator("#image-canvas").bounding_box()
    scale = box["width"] / CYLINDER_SIZE_PX
    page.mouse.click(box["x"] + (x + 0.5) * scale, box["y"] + (y + 0.5) * scale)
    page.wait_for_selector('#spectrum-plot circle[data-series="A"]')
    points = page.evaluate(
        """() => [...document.querySelectorAll('#spectrum-plot circle[data-series="A"]')]
            .map((c) => [Number(c.dataset.x), Number(c.dataset.y)])"""
    )
    bands = exr.band_names()
    assert [p[0] for p in points] == [float(n[3:-2].replace(",", ".")) for n in bands]
    np.testing.assert_array_equal([p[1] for p in points], [float(exr.channels[n][y, x]) for n in bands])
    assert page.inner_text('[data-slot="A"] .pixel-title') == f"Pixel A: ({x}, {y})"
    # ℓ₁ at the wavelength slider's λ (∝ λ from the 550 nm the EXR holds), as the ellipse hover.
    nm = float(page.inner_text("#band-label").split()[0])
    l1_row = page.get_attribute('[data-slot="A"] tr[data-key="l1_um"]', "data-value")
    assert float(l1_row) == pytest.approx(float(exr.channels["coherence.l1_um"][y, x]) * nm / 550.0, rel=1e-6)
    assert f"at {nm:.0f} nm" in page.inner_text('[data-slot="A"] caption')
    angle_row = float(page.get_attribute('[data-slot="A"] tr[data-key="angle"]', "data-value"))
    assert angle_row == pytest.approx(np.degrees(float(exr.channels["coherence.angle"][y, x])), rel=1e-6)
    # Second pixel (slot B), by keyboard-accessible form: two spectra in the plot.
    page.check('input[name="inspect-slot"][value="B"]')
    page.fill("#inspect-x", "0")
    page.fill("#inspect-y", "0")
    page.press("#inspect-y", "Enter")
    page.wait_for_selector('#spectrum-plot circle[data-series="B"]')
    assert page.inner_text('[data-slot="B"] .pixel-title') == "Pixel B: (0, 0)"
    screenshot(page, "viewer_inspector")


def test_running_job_progress_bar_advances(page: Any, live_service: LiveService) -> None:
    page.goto(f"{live_service.base_url}/#/jobs")
    page.wait_for_function("() => document.querySelector('#scene-example').options.length > 1")
    page.select_option("#scene-example", "thin_film_cylinder_light.json")
    page.fill("#override-spp", "64")
    page.fill("#override-width", "48")
    page.fill("#override-height", "48")
    page.fill("#override-chunks", "4")
    page.fill("#job-name", "progress test")
    page.click("#submit-job")
    page.wait_for_function(
        "() => document.querySelector('#submit-status').textContent.startsWith('submitted')"
    )
    job_id = page.inner_text("#submit-status").split()[-1]
    row = f'tr[data-job-id="{job_id}"]'
    page.wait_for_selector(row)
    values: list[float] = []
    deadline = time.monotonic() + 120
    running_seen = False
    preview_seen = False
    while time.monotonic() < deadline:
        values.append(float(page.evaluate(f"() => document.querySelector('{row} progress').value")))
        status = page.get_attribute(row, "data-status")
        if status == "running" and not running_seen:
            running_seen = True
            screenshot(page, "jobs_running")
        if status == "running" and not preview_seen:
            # Before any chunk finishes the image endpoints answer 409; afterwards they serve a preview
            # merged from the finished chunks (flagged partial).
            view = live_service.get(f"/v1/jobs/{job_id}").json()
            layers = live_service.get(f"/v1/jobs/{job_id}/layers")
            if view["status"] == "running" and view["chunks_done"] == 0 and layers.status_code == 409:
                pass
            elif layers.status_code == 200 and view["status"] == "running":
                catalogue = layers.json()
                assert catalogue["partial"] is True and (catalogue["width"], catalogue["height"]) == (48, 48)
                assert live_service.get(f"/v1/jobs/{job_id}/display.png").status_code == 200
                preview_seen = True
        if status in ("succeeded", "failed", "canceled"):
            break
        page.wait_for_timeout(50)
    assert page.get_attribute(row, "data-status") == "succeeded"
    assert preview_seen  # 4 chunks of ≈0.3 s each, polled every 50 ms
    assert live_service.get(f"/v1/jobs/{job_id}/layers").json()["partial"] is False
    values.append(float(page.evaluate(f"() => document.querySelector('{row} progress').value")))
    intermediate = sorted({v for v in values if 0.0 < v < 1.0})
    # 4 chunks on one worker: at least the 25 %, 50 %, 75 % steps are shown before 100 %.
    assert len(intermediate) >= 2, values
    assert values == sorted(values)  # never goes backwards
    assert values[-1] == 1.0
    assert re.fullmatch(r"[\d.]+[kMG]?", page.inner_text(f"{row} .job-rate"))  # the header says samples/s
    assert page.get_attribute(f"{row} .job-rate", "title").endswith(" samples per second")
    screenshot(page, "jobs_done")


def test_compare_view_shows_delta_e(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob, cylinder_job_reseeded: RenderedJob
) -> None:
    page.goto(f"{live_service.base_url}/#/jobs")
    a, b = cylinder_job.job_id, cylinder_job_reseeded.job_id
    page.wait_for_selector(f'tr[data-job-id="{a}"]')
    page.check(f'tr[data-job-id="{a}"] .job-select')
    page.check(f'tr[data-job-id="{b}"] .job-select')
    page.click("#compare-selected")
    page.wait_for_function("() => Number(document.querySelector('.compare')?.dataset.ready) >= 1")
    # Opens at a's automatic exposure (not 0 EV), the one regression runs use.
    auto_ev = live_service.get(f"/v1/jobs/{a}/layers").json()["exposure_ev"]
    left = canvas_rgb(page, ".compare-left")
    assert np.abs(left - display_rgb8(cylinder_job.exr.rgb, auto_ev, "clamp")).max() <= 1
    page.fill(".compare-split", "30")
    screenshot(page, "compare_split")
    page.select_option(".compare-mode", "de2000")
    page.wait_for_function("() => Number(document.querySelector('.compare').dataset.ready) >= 2")
    response = live_service.get("/v1/compare", a=a, b=b, mode="de2000")
    assert float(response.headers["X-Exposure-EV"]) == auto_ev
    import json

    stats = json.loads(response.headers["X-Stats"])
    assert float(page.get_attribute(".compare-stats", "data-mean")) == pytest.approx(stats["mean"], rel=1e-12)
    assert "ΔE₀₀" in page.inner_text(".compare-stats")
    diff = np.frombuffer(response.content, dtype="<f4").reshape(CYLINDER_SIZE_PX, CYLINDER_SIZE_PX)
    assert np.abs(canvas_rgb(page, ".compare-diff") - viridis8(diff / 10.0)).max() <= 1
    # Hover readout: both images' values and the map's at the pixel under the pointer.
    stage = page.locator(".compare-stage").bounding_box()
    scale = stage["width"] / CYLINDER_SIZE_PX
    page.mouse.move(stage["x"] + 6.5 * scale, stage["y"] + 9.5 * scale)
    readout = page.inner_text(".compare-readout")
    assert readout.startswith("(6, 9) linear R G B a: ")
    assert float(readout.rsplit("de2000 ", 1)[1]) == pytest.approx(float(diff[9, 6]), rel=5e-3)  # 3 digits
    screenshot(page, "compare_de2000")
    page.select_option(".compare-mode", "flip")
    page.wait_for_function("() => Number(document.querySelector('.compare').dataset.ready) >= 3")
    flip_stats = json.loads(live_service.get("/v1/compare", a=a, b=b, mode="flip").headers["X-Stats"])
    assert float(page.get_attribute(".compare-stats", "data-p95")) == pytest.approx(
        flip_stats["p95"], rel=1e-12
    )
    assert "ꟻLIP" in page.inner_text(".compare-stats")
    screenshot(page, "compare_flip")


def test_controls_are_labelled_and_keyboard_reachable(
    page: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_viewer(page, live_service, cylinder_job.job_id)
    unlabelled = page.evaluate(
        """() => [...document.querySelectorAll('input, select, button, canvas, [tabindex]')]
            .filter((e) => e.offsetParent !== null)
            .filter((e) => !(e.labels && e.labels.length) && !e.getAttribute('aria-label')
                           && !(e.tagName === 'BUTTON' && e.textContent.trim()))
            .map((e) => e.outerHTML.slice(0, 80))"""
    )
    assert unlabelled == []
    order = []
    page.focus("#token")
    for _ in range(40):
        page.keyboard.press("Tab")
        order.append(page.evaluate("() => document.activeElement.id || document.activeElement.tagName"))
    for control in (
        "display-mode",
        "band-slider",
        "ev-slider",
        "tonemap",
        "ellipse-spacing",
        "viewport",
        "inspect-x",
    ):
        assert control in order, order
    # Tab order follows the visual order of the controls.
    assert (
        order.index("display-mode")
        < order.index("ev-slider")
        < order.index("viewport")
        < order.index("inspect-x")
    )
    page.focus("#viewport")
    before = page.inner_text("#zoom-label")
    page.keyboard.press("+")
    assert page.inner_text("#zoom-label") != before
    # Arrow keys move the exposure slider by its step (0.1 EV).
    page.focus("#ev-slider")
    ev = float(page.input_value("#ev-slider"))
    page.keyboard.press("ArrowLeft")
    assert page.input_value("#ev-value") == f"{ev - 0.1:.2f}"


def test_narrow_viewport_has_no_horizontal_overflow(
    chromium: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    context = chromium.new_context(viewport={"width": 375, "height": 667}, device_scale_factor=2)
    context.add_init_script(f"window.localStorage.setItem('hgrender.token', {live_service.token!r});")
    page = context.new_page()
    try:
        for route, name in (("#/jobs", "narrow_jobs"), (f"#/view/{cylinder_job.job_id}", "narrow_viewer")):
            page.goto(f"{live_service.base_url}/{route}")
            page.wait_for_load_state("networkidle")
            page.wait_for_timeout(300)
            widths = page.evaluate(
                "() => [document.documentElement.scrollWidth, document.documentElement.clientWidth]"
            )
            assert widths[0] <= widths[1], (route, widths)
            screenshot(page, name)
    finally:
        context.close()


def test_cancel_and_delete_from_the_job_list(page: Any, live_service: LiveService) -> None:
    # Long enough to be still queued or running whenever the click comes: 64×64 px × 16384 spp on one
    # worker renders for tens of seconds (256 spp took under a second once small jobs got faster);
    # canceled, it stops within a render pass.
    job_id = live_service.admin.submit(cylinder_scene(width=64, height=64, spp=16384), name="to cancel")["id"]
    page.goto(f"{live_service.base_url}/#/jobs")
    row = f'tr[data-job-id="{job_id}"]'
    page.wait_for_selector(row)
    page.click(f"{row} .job-cancel")
    page.wait_for_function(f"() => document.querySelector('{row}').dataset.status === 'canceled'")
    assert live_service.admin.get(job_id)["status"] == "canceled"
    page.once("dialog", lambda dialog: dialog.accept())
    page.click(f"{row} .job-delete")
    page.wait_for_selector(row, state="detached")
    assert live_service.get(f"/v1/jobs/{job_id}").status_code == 404


def test_upload_a_json_scene_with_overrides(page: Any, live_service: LiveService, tmp_path: Any) -> None:
    import json

    scene_file = tmp_path / "uploaded.json"
    scene_file.write_text(json.dumps(cylinder_scene()))
    page.goto(f"{live_service.base_url}/#/jobs")
    page.wait_for_function("() => document.querySelector('#scene-example').options.length > 1")
    page.set_input_files("#scene-file", str(scene_file))
    page.fill("#override-width", "16")
    page.fill("#override-height", "12")
    page.fill("#override-spp", "2")
    page.fill("#job-name", "uploaded")
    page.click("#submit-job")
    page.wait_for_function(
        "() => document.querySelector('#submit-status').textContent.startsWith('submitted')"
    )
    job_id = page.inner_text("#submit-status").split()[-1]
    final = live_service.wait_final(job_id)
    assert final["status"] == "succeeded" and final["spp"] == 2 and final["name"] == "uploaded"
    layers = live_service.get(f"/v1/jobs/{job_id}/layers").json()
    assert (layers["width"], layers["height"]) == (16, 12)  # the overrides were edited into film


def test_viewer_refines_a_noise_target_job_round_by_round(page: Any, live_service: LiveService) -> None:
    """Issue 16 item 4: opened while a noise-target job runs, the viewer shows the image of the rounds
    finished so far and reloads it when a newer one is published (polling the job every second), then
    the final image. A 0.3 % band-mean target from 2 spp on the 24² cylinder-light plane takes rounds of
    2, 18, 162, 1458, … spp (8× growth cap); the first round's preview and that of a later round
    lasting seconds (published: it outlasts 10× the first publication) are each shown ≥ 1 s."""
    job_id = live_service.admin.submit(cylinder_scene(spp=2), name="refining", target_rel_error=0.003)["id"]
    deadline = time.monotonic() + 120
    while not (live_service.admin.get(job_id)["noise_target"].get("rounds") or []):
        assert time.monotonic() < deadline and live_service.admin.get(job_id)["status"] in (
            "queued",
            "running",
        )
        time.sleep(0.05)
    open_viewer(page, live_service, job_id)
    shown: dict[int, np.ndarray] = {}  # preview spp → canvas shown for it
    while time.monotonic() < deadline:
        # One evaluate reads the line and the canvas together (no refresh can run in between).
        spp, text = page.evaluate(
            "() => [document.querySelector('#viewer-size').dataset.spp,"
            " document.querySelector('#viewer-size').textContent]"
        )
        canvas = canvas_rgb(page)
        if spp != page.get_attribute("#viewer-size", "data-spp"):
            continue  # refreshed between the two reads
        if not spp:
            break  # the final image (not a preview)
        if int(spp) not in shown:
            shown[int(spp)] = canvas
            assert f"preview at {spp} spp" in text
            screenshot(page, f"viewer_refining_{len(shown)}")
        page.wait_for_timeout(50)
    final = live_service.wait_final(job_id)
    assert final["status"] == "succeeded"
    rounds_spp = [int(r["spp"]) for r in final["noise_target"]["rounds"]]
    # At least two rounds' previews were shown one after the other without reopening, each a round's
    # image (not the final one), and each different (more samples: less noise).
    assert len(shown) >= 2, (sorted(shown), rounds_spp)
    assert set(shown) <= set(rounds_spp[:-1]), (sorted(shown), rounds_spp)
    canvases = [shown[spp] for spp in sorted(shown)]
    assert all(np.abs(a - b).max() > 0 for a, b in itertools.pairwise(canvases))
    # Then the final image replaces the last preview at the exposure the user had: the server's display.
    ev = float(page.get_attribute("#image-canvas", "data-ev"))
    png = live_service.get(f"/v1/jobs/{job_id}/display.png", ev=ev, tonemap="clamp").content
    server = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int64)
    assert np.abs(canvas_rgb(page) - server).max() <= 1
    assert page.is_enabled("#download-exr")
    screenshot(page, "viewer_refined_final")
