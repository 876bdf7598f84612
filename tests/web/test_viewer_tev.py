"""The viewer's issue-14 behaviour in headless Chromium at 1400×900: exposure range and tev's offset/gamma,
ellipses at an absolute µm scale, downloads, the pixel inspector's markers/axes/readouts, the log colour
scale of layers with zeros, wrong job ids, the job list, tev's keys, a dropped EXR, and the page without a
token. Assertions are on what is shown (canvas pixels, DOM text, positions inside the 1400×900 window).
Screenshots: test-artifacts/tev_*.png."""

from __future__ import annotations

import base64
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.imaging import tone_map
from tests.support.browser import canvas_rgb, drawn_count, redrawn, screenshot, token_page, viridis8
from tests.support.live_service import LiveService, RenderedJob
from tests.support.scenes import CYLINDER_SIZE_PX, cylinder_scene

pytestmark = pytest.mark.browser
WIDTH, HEIGHT = 1400, 900


@pytest.fixture
def wide(chromium: Any, live_service: LiveService) -> Iterator[Any]:
    """A 1400×900 page with the admin token; fails the test on page errors."""
    with token_page(chromium, live_service.token, WIDTH, HEIGHT, accept_downloads=True) as page:
        yield page


def open_image(page: Any, live_service: LiveService, job_id: str) -> None:
    page.goto(f"{live_service.base_url}/#/view/{job_id}")
    page.wait_for_function("() => Number(document.querySelector('#image-canvas').dataset.drawn) >= 1")
    page.wait_for_function("() => document.querySelector('#ellipse-overlay').dataset.count !== undefined")


def box(page: Any, selector: str) -> dict[str, float]:
    return page.locator(selector).bounding_box()


def srgb_curve(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)


def test_image_page_fits_1400x900_with_stats_and_colour_bar(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    wide.check("#show-ellipses")
    wide.wait_for_selector("#ellipse-legend canvas")
    count = drawn_count(wide)
    wide.select_option("#display-mode", "coherence.l1_um")
    redrawn(wide, count)
    for selector in (
        "#viewport",
        "#legend canvas",
        "#histogram",
        "#histogram-label",
        "#ellipse-legend canvas",
    ):
        b = box(wide, selector)
        assert b is not None and b["y"] >= 0 and b["y"] + b["height"] <= HEIGHT, (selector, b)
        assert b["x"] + b["width"] <= WIDTH, (selector, b)
    scroll = wide.evaluate("() => [document.documentElement.scrollHeight, window.innerHeight]")
    assert scroll[0] <= scroll[1]  # nothing below the fold
    assert box(wide, "#viewport")["height"] > 500  # the image gets the room
    screenshot(wide, "tev_fits_1400x900")


def test_exposure_range_holds_auto_and_says_when_it_clamps(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    auto = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/layers").json()["exposure_ev"]
    lo, hi = float(wide.get_attribute("#ev-slider", "min")), float(wide.get_attribute("#ev-slider", "max"))
    assert lo <= auto <= hi and float(wide.input_value("#ev-slider")) == pytest.approx(auto, abs=0.05)
    assert "clamped" not in wide.inner_text("#ev-note")
    # An exposure beyond the slider (typed into the box) is used as typed, and the note says so.
    count = drawn_count(wide)
    wide.fill("#ev-value", str(hi + 5))
    wide.dispatch_event("#ev-value", "change")
    redrawn(wide, count)
    assert float(wide.get_attribute("#image-canvas", "data-ev")) == hi + 5
    assert wide.input_value("#ev-slider") == str(int(hi))
    assert f"clamped: the slider ends at {int(hi)} EV" in wide.inner_text("#ev-note")
    screenshot(wide, "tev_exposure_clamped")
    # tev's offset and gamma: v = (x·2^EV + offset), clamp, then v^(1/γ).
    ev, offset, gamma = auto, 0.05, 1.8
    count = drawn_count(wide)
    wide.fill("#ev-value", f"{ev}")
    wide.dispatch_event("#ev-value", "change")
    redrawn(wide, count)
    for selector, value in (("#offset", str(offset)), ("#gamma", str(gamma))):
        wide.fill(selector, value)
        wide.dispatch_event(selector, "change")
    count = drawn_count(wide)
    wide.select_option("#transfer", "gamma")
    redrawn(wide, count)
    linear = cylinder_job.exr.rgb.astype(np.float64) * 2.0 ** round(ev, 2) + offset
    expected = np.floor(np.power(tone_map(linear, "clamp"), 1 / gamma) * 255 + 0.5)
    assert np.abs(canvas_rgb(wide) - expected).max() <= 1
    # Offset 0 and the sRGB curve again: the plain display transform.
    wide.fill("#offset", "0")
    wide.dispatch_event("#offset", "change")
    count = drawn_count(wide)
    wide.select_option("#transfer", "srgb")
    redrawn(wide, count)
    plain = np.floor(srgb_curve(tone_map(cylinder_job.exr.rgb * 2.0 ** round(ev, 2), "clamp")) * 255 + 0.5)
    assert np.abs(canvas_rgb(wide) - plain).max() <= 1


def ellipse_shapes(page: Any) -> list[dict[str, float]]:
    return page.evaluate(
        """() => [...document.querySelectorAll('#ellipse-overlay ellipse')].map((e) => ({
            x: Number(e.dataset.x), y: Number(e.dataset.y), rx: Number(e.getAttribute('rx')),
            ry: Number(e.getAttribute('ry')), l1: Number(e.dataset.l1Um), l2: Number(e.dataset.l2Um),
            screenMinor: Math.min(e.getBoundingClientRect().width, e.getBoundingClientRect().height)}))"""
    )


def test_ellipses_are_drawn_to_an_absolute_um_scale_in_every_mode(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob, diagonal_cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    wide.check("#show-ellipses")
    wide.select_option("#ellipse-scale", "20")
    wide.wait_for_function("() => document.querySelector('#ellipse-overlay').dataset.umPerPx === '20'")
    nm = float(wide.inner_text("#band-label").split()[0])
    l1 = cylinder_job.exr.channels["coherence.l1_um"]
    zoom = float(wide.inner_text("#zoom-label").rstrip("%")) / 100
    for shape in ellipse_shapes(wide):
        # ℓ₁ at the slider's λ (∝ λ from 550 nm) over 20 µm per image pixel.
        assert shape["l1"] == pytest.approx(float(l1[int(shape["y"]), int(shape["x"])]) * nm / 550, rel=1e-6)
        assert shape["rx"] == pytest.approx(shape["l1"] / 20, rel=1e-6)
        assert shape["ry"] == pytest.approx(max(shape["l2"] / 20, 1.5 / zoom), rel=1e-3)
    note = wide.inner_text("#ellipse-legend")
    assert f"λ = {nm:.0f} nm" in note and "1 image px = 20 µm" in note
    # The scale bar: a round length in µm, as long on screen as that length at 20 µm/px and this zoom.
    bar = wide.locator("#scale-bar")
    length_um = float(bar.get_attribute("data-length-um"))
    width_px = box(wide, "#scale-bar .scale-bar-line")["width"]
    assert width_px == pytest.approx(length_um / 20 * zoom, abs=1.5)
    assert re.match(r"^\d+(\.\d+)? µm \(ellipses at \d+ nm\)$", wide.inner_text(".scale-bar-label"))
    # Another wavelength: lengths scale ∝ λ and the label says which.
    wide.fill("#band-slider", "1")
    nm_1 = float(wide.inner_text("#band-label").split()[0])
    assert f"λ = {nm_1:.0f} nm" in wide.inner_text("#ellipse-legend")
    first = ellipse_shapes(wide)[0]
    assert first["rx"] == pytest.approx(
        float(l1[int(first["y"]), int(first["x"])]) * nm_1 / 550 / 20, rel=1e-6
    )
    # A diagnostic display mode keeps the ellipses, none thinner than 1.5 screen px.
    count = drawn_count(wide)
    wide.select_option("#display-mode", "coherence.l1_um")
    redrawn(wide, count)
    shapes = ellipse_shapes(wide)
    assert len(shapes) >= 4 and min(s["screenMinor"] for s in shapes) >= 1.4
    screenshot(wide, "tev_ellipses_um_scale")
    # The same setting on another job: the same µm per pixel (comparable across jobs).
    open_image(wide, live_service, diagonal_cylinder_job.job_id)
    wide.check("#show-ellipses")
    wide.wait_for_function("() => document.querySelectorAll('#ellipse-overlay ellipse').length > 0")
    assert wide.get_attribute("#ellipse-overlay", "data-um-per-px") == "20"


def test_downloads_exr_png_diagnostics_and_spectrum_csv(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob, tmp_path: Path
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)

    def download(selector: str) -> Path:
        with wide.expect_download() as info:
            wide.click(selector)
        path = tmp_path / info.value.suggested_filename
        info.value.save_as(path)
        return path

    exr = download("#download-exr")
    assert exr.suffix == ".exr"
    assert exr.read_bytes() == live_service.get(f"/v1/jobs/{cylinder_job.job_id}/artifacts/image.exr").content
    png = download("#download-png")
    from PIL import Image

    assert np.array_equal(np.asarray(Image.open(png).convert("RGB"), dtype=np.int64), canvas_rgb(wide))
    diagnostics = read_exr(download("#download-diagnostics")).channels
    np.testing.assert_array_equal(
        diagnostics["coherence.l1_um"], cylinder_job.exr.channels["coherence.l1_um"]
    )
    wide.fill("#inspect-x", "5")
    wide.fill("#inspect-y", "7")
    wide.press("#inspect-y", "Enter")
    wide.wait_for_selector('[data-slot="A"]:not([hidden]) .pixel-csv')
    rows = download('[data-slot="A"] .pixel-csv').read_text().splitlines()
    assert rows[0].startswith("# job ") and "x=5 y=7" in rows[0] and rows[1] == "wavelength_nm,radiance"
    names = cylinder_job.exr.band_names()
    values = [tuple(map(float, row.split(","))) for row in rows[2:]]
    assert [v[0] for v in values] == [float(n[3:-2].replace(",", ".")) for n in names]
    assert [v[1] for v in values] == [float(cylinder_job.exr.channels[n][7, 5]) for n in names]


def test_inspector_markers_axes_legend_and_hover_readouts(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    canvas = box(wide, "#image-canvas")
    scale = canvas["width"] / CYLINDER_SIZE_PX
    wide.mouse.click(canvas["x"] + 10.5 * scale, canvas["y"] + 4.5 * scale)
    wide.wait_for_selector('#marker-overlay g[data-slot="A"]')
    wide.check('input[name="inspect-slot"][value="B"]')
    wide.mouse.click(canvas["x"] + 3.5 * scale, canvas["y"] + 20.5 * scale)
    wide.wait_for_selector('#marker-overlay g[data-slot="B"]')
    # Markers sit on the inspected pixels (screen positions), legend names both.
    for slot, (x, y) in (("A", (10, 4)), ("B", (3, 20))):
        marker = box(wide, f'#marker-overlay g[data-slot="{slot}"] rect')
        assert marker["x"] == pytest.approx(canvas["x"] + x * scale, abs=2)
        assert marker["y"] == pytest.approx(canvas["y"] + y * scale, abs=2)
        assert f"{slot} ({x}, {y})" in wide.inner_text("#spectrum-legend")
    # Real axes: x ticks are wavelengths in nm within the bands' range, the y axis names its unit.
    ticks = [float(t) for t in wide.locator("#spectrum-plot .x-tick").all_text_contents()]
    wavelengths = [float(n[3:-2].replace(",", ".")) for n in cylinder_job.exr.band_names()]
    assert len(ticks) >= 3 and wavelengths[0] <= min(ticks) and max(ticks) <= wavelengths[-1]
    assert all(t % 50 == 0 for t in ticks)  # round 1-2-5 steps
    assert "wavelength λ [nm]" in wide.text_content("#spectrum-plot .x-label")
    assert "W·m⁻²·sr⁻¹·nm⁻¹" in wide.text_content("#spectrum-plot .y-label")
    # Hovering the plot reads out both pixels at the nearest band, in nm.
    dot = box(wide, '#spectrum-plot circle[data-series="A"] >> nth=3')
    wide.mouse.move(dot["x"] + dot["width"] / 2, dot["y"] + dot["height"] / 2)
    assert wide.inner_text("#spectrum-readout").startswith(f"λ {wavelengths[3]:.1f} nm: A ")
    assert " B " in wide.inner_text("#spectrum-readout")
    screenshot(wide, "tev_inspector")
    # Hover over the image: the pixel's values in the current mode.
    wide.mouse.move(canvas["x"] + 10.5 * scale, canvas["y"] + 4.5 * scale)
    readout = wide.inner_text("#hover-readout")
    assert readout.startswith("(10, 4) linear R G B: ")
    red = float(readout.split(": ")[1].split()[0])
    assert red == pytest.approx(float(cylinder_job.exr.channels["R"][4, 10]), rel=5e-3)
    # Zoomed in (≥ 48 screen px per pixel) the values are drawn on the pixels.
    assert wide.get_attribute("#value-canvas", "data-values") == "0"
    for _ in range(3):
        wide.click("#zoom-in")
    assert int(wide.get_attribute("#value-canvas", "data-values")) > 0
    screenshot(wide, "tev_values_on_pixels")


def test_log_scale_works_when_the_first_percentile_is_zero(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    catalogue = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/layers").json()
    band = next(layer for layer in catalogue["layers"] if layer["kind"] == "band" and layer["p01"] <= 0)
    index = [layer["name"] for layer in catalogue["layers"] if layer["kind"] == "band"].index(band["name"])
    count = drawn_count(wide)
    wide.select_option("#display-mode", "band")
    redrawn(wide, count)
    wide.fill("#band-slider", str(index))
    count = drawn_count(wide)
    wide.check("#log-scale")
    redrawn(wide, count)
    # symlog: s(v) = sign(v)·log10(1 + |v|/c), c = max(|p01|, |p99|)·1e-3, mapped from s(p01) to s(p99).
    lo, hi = band["p01"], band["p99"]
    c = max(abs(lo), abs(hi)) * 1e-3

    def s(v: np.ndarray) -> np.ndarray:
        return np.sign(v) * np.log10(1 + np.abs(v) / c)

    values = cylinder_job.exr.channels[band["name"]].astype(np.float64)
    expected = viridis8((s(values) - s(lo)) / (s(hi) - s(lo)))
    shown = canvas_rgb(wide)
    assert np.abs(shown - expected).max() <= 1
    linear = viridis8((values - lo) / (hi - lo))
    assert np.abs(shown - linear).max() > 20  # the log scale changed the picture
    assert wide.get_attribute("#legend", "data-scale") == "symlog"
    assert "symlog: linear within ±" in wide.inner_text("#legend")
    screenshot(wide, "tev_symlog")


def test_wrong_job_id_says_no_such_job_and_clears_the_image(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    for wrong in ("nonsense", "0" * 32):
        wide.goto(f"{live_service.base_url}/#/view/{wrong}")
        wide.wait_for_function("() => !document.querySelector('#error').hidden")
        assert wide.inner_text("#error").startswith(f"no such job: {wrong}")
        assert wide.inner_text("#viewer-title") == "No such job"
        assert (
            wide.get_attribute("#image-canvas", "width"),
            wide.get_attribute("#image-canvas", "height"),
        ) == ("1", "1")
        assert wide.locator("#ellipse-overlay ellipse").count() == 0
        assert wide.inner_text("#legend") == ""
    screenshot(wide, "tev_no_such_job")


def test_job_list_columns_names_eta_and_regression_filter(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    regression = live_service.render(
        cylinder_scene(spp=1, width=8, height=8), "regression cylinder (run 0123abcd)"
    )
    long_job = live_service.admin.submit(cylinder_scene(width=64, height=64, spp=16384), name="cylinder")[
        "id"
    ]
    try:
        wide.goto(f"{live_service.base_url}/#/jobs")
        row = wide.locator(f'tr[data-job-id="{cylinder_job.job_id}"]')
        row.wait_for()
        assert row.locator(".job-name").inner_text() == f"cylinder · {cylinder_job.job_id[:8]}"
        assert row.locator(".job-size").inner_text() == f"{CYLINDER_SIZE_PX}×{CYLINDER_SIZE_PX}"
        assert row.locator(".job-spp").inner_text() == "4"
        assert re.search(r"\d\d:\d\d:\d\d", row.locator(".job-created").inner_text())
        # Two jobs of one scene name are told apart by their ids.
        names = wide.locator(".job-name").all_inner_texts()
        assert len([n for n in names if n.startswith("cylinder · ")]) >= 2 and len(set(names)) == len(names)
        # Regression jobs are hidden by default, shown on request.
        assert wide.locator(f'tr[data-job-id="{regression}"]').count() == 0
        assert "regression job" in wide.inner_text("#jobs-hidden")
        wide.uncheck("#hide-regression")
        wide.locator(f'tr[data-job-id="{regression}"]').wait_for()
        # ETA of the running job from the SSE progress events' eta_s.
        eta = wide.locator(f'tr[data-job-id="{long_job}"] .job-eta')
        eta.wait_for()
        eta_shown = (
            "(id) => /\\d+(\\.\\d)? (s|min)/"
            ".test(document.querySelector(`tr[data-job-id='${id}'] .job-eta`).textContent)"
        )
        wide.wait_for_function(
            eta_shown,
            arg=long_job,
            timeout=60_000,
        )
        screenshot(wide, "tev_job_list")
    finally:
        live_service.admin.cancel(long_job)


def test_tev_keys_work_without_clicking_the_image(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    open_image(wide, live_service, cylinder_job.job_id)
    ev = float(wide.get_attribute("#image-canvas", "data-ev"))
    wide.locator("body").focus()
    count = drawn_count(wide)
    wide.keyboard.press("e")
    redrawn(wide, count)
    assert float(wide.get_attribute("#image-canvas", "data-ev")) == pytest.approx(ev + 0.5)
    count = drawn_count(wide)
    wide.keyboard.press("Shift+E")
    wide.keyboard.press("Shift+E")
    wide.wait_for_function(
        "(n) => Number(document.querySelector('#image-canvas').dataset.drawn) >= n + 2", arg=count
    )
    assert float(wide.get_attribute("#image-canvas", "data-ev")) == pytest.approx(ev - 0.5)
    count = drawn_count(wide)
    wide.keyboard.press("n")
    redrawn(wide, count)
    assert float(wide.get_attribute("#image-canvas", "data-ev")) == ev
    count = drawn_count(wide)
    wide.keyboard.press("3")  # the third display mode (the first diagnostic layer)
    redrawn(wide, count)
    assert wide.get_attribute("#image-canvas", "data-mode") == wide.evaluate(
        "() => document.querySelector('#display-mode').options[2].value"
    )
    before = wide.evaluate("() => document.querySelector('#stage').style.transform")
    wide.keyboard.press("ArrowLeft")
    after = wide.evaluate("() => document.querySelector('#stage').style.transform")
    assert before != after
    wide.keyboard.press("+")
    wide.keyboard.press("f")
    assert wide.evaluate("() => document.querySelector('#stage').style.transform") == before
    wide.keyboard.press("?")
    assert wide.locator("#help").is_visible()
    text = wide.inner_text("#help")
    for key in ("Shift+E", "exposure", "1…9", "fit", "pan", "Shift+N"):
        assert key in text, key
    screenshot(wide, "tev_keys_overlay")
    wide.keyboard.press("Escape")
    assert not wide.locator("#help").is_visible()


def test_dropped_exr_is_decoded_by_the_service_and_shown(
    wide: Any, live_service: LiveService, cylinder_job: RenderedJob, tmp_path: Path
) -> None:
    exr = tmp_path / "local.exr"
    live_service.admin.download(cylinder_job.job_id, "image.exr", exr)
    wide.goto(f"{live_service.base_url}/#/view")
    wide.wait_for_selector("#viewer-panel:not([hidden])")
    payload = base64.b64encode(exr.read_bytes()).decode()
    wide.evaluate(
        """(b64) => {
            const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
            const transfer = new DataTransfer();
            transfer.items.add(new File([bytes], "local.exr", {type: "image/x-exr"}));
            window.dispatchEvent(new DragEvent("dragenter", {dataTransfer: transfer}));
            window.dispatchEvent(new DragEvent("drop", {dataTransfer: transfer}));
        }""",
        payload,
    )
    wide.wait_for_function("() => Number(document.querySelector('#image-canvas').dataset.drawn) >= 1")
    assert wide.inner_text("#viewer-title") == "Local file local.exr"
    assert "dropped EXR" in wide.inner_text("#viewer-size")
    assert wide.locator("#download-exr").is_disabled()
    ev = float(wide.get_attribute("#image-canvas", "data-ev"))
    expected = np.floor(srgb_curve(tone_map(cylinder_job.exr.rgb * 2.0**ev, "clamp")) * 255 + 0.5)
    assert np.abs(canvas_rgb(wide) - expected).max() <= 1
    screenshot(wide, "tev_dropped_exr")
    # Not an EXR: a clear error, nothing opened.
    wide.set_input_files(
        "#exr-file", files=[{"name": "notes.exr", "mimeType": "image/x-exr", "buffer": b"hello"}]
    )
    wide.wait_for_function("() => !document.querySelector('#error').hidden")
    assert "file: not an OpenEXR file" in wide.inner_text("#error")


def test_without_a_token_the_page_says_how_to_get_one(chromium: Any, live_service: LiveService) -> None:
    context = chromium.new_context(viewport={"width": WIDTH, "height": HEIGHT})
    page = context.new_page()
    try:
        page.goto(f"{live_service.base_url}/#/jobs")
        page.wait_for_selector("#token-help:not([hidden])")
        assert not page.locator("#jobs-empty").is_visible()
        text = page.inner_text("#token-help")
        assert "No API token" in text and "admin.token" in text and "hgrender token create" in text
        screenshot(page, "tev_no_token")
        # A wrong token: the service's 401, and the same help.
        page.fill("#token", "not-a-token")
        page.click("#token-form button")
        page.wait_for_function("() => !document.querySelector('#error').hidden")
        assert "401" in page.inner_text("#error")
        assert page.locator("#token-help").is_visible()
        # The right one: the help goes away.
        page.fill("#token", live_service.token)
        page.click("#token-form button")
        page.wait_for_selector("#token-help", state="hidden")
    finally:
        context.close()
