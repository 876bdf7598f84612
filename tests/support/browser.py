"""Driving the viewer in headless Chromium (Playwright): pages with a token, screenshots, and what the
canvas shows (its pixels, how often it was drawn, the viridis colour map it must use)."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

ARTIFACTS_DIR = Path(__file__).resolve().parents[2] / "test-artifacts"
"""Where screenshots go (look at them)."""


@contextlib.contextmanager
def token_page(chromium: Any, token: str, width: int, height: int, **context_options: Any) -> Iterator[Any]:
    """A ``width``×``height`` page with ``token`` in localStorage; fails the test on page errors."""
    context = chromium.new_context(viewport={"width": width, "height": height}, **context_options)
    context.add_init_script(f"window.localStorage.setItem('hgrender.token', {token!r});")
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        yield page
    finally:
        context.close()
    assert not errors, f"page errors: {errors}"


def screenshot(page: Any, name: str) -> Path:
    ARTIFACTS_DIR.mkdir(exist_ok=True)
    path = ARTIFACTS_DIR / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


# Matt Zucker's polynomial fit of viridis, as in web/js/colormap.js (the canvas must show exactly it).
VIRIDIS = np.array(
    [
        [0.2777273272234177, 0.005407344544966578, 0.3340998053353061],
        [0.1050930431085774, 1.404613529898575, 1.384590162594685],
        [-0.3308618287255563, 0.214847559468213, 0.09509516302823659],
        [-4.634230498983486, -5.799100973351585, -19.33244095627987],
        [6.228269936347081, 14.17993336680509, 56.69055260068105],
        [4.776384997670288, -13.74514537774601, -65.35303263337234],
        [-5.435455855934631, 4.645852612178535, 26.3124352495832],
    ]
)


def viridis8(t: np.ndarray) -> np.ndarray:
    t = np.clip(np.nan_to_num(t), 0.0, 1.0)[..., None]
    value = np.zeros((*t.shape[:-1], 3)) + VIRIDIS[6]
    for k in range(5, -1, -1):
        value = VIRIDIS[k] + t * value
    return np.floor(np.clip(value, 0.0, 1.0) * 255.0 + 0.5).astype(np.int64)


def canvas_rgb(page: Any, selector: str = "#image-canvas") -> np.ndarray:
    """The canvas's pixels (H, W, 3) as 8-bit values."""
    data = page.evaluate(
        """(selector) => {
            const canvas = document.querySelector(selector);
            const pixels = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height);
            return {width: canvas.width, height: canvas.height, data: Array.from(pixels.data)};
        }""",
        selector,
    )
    rgba = np.array(data["data"], dtype=np.int64).reshape(data["height"], data["width"], 4)
    return rgba[..., :3]


def redrawn(page: Any, count_before: int) -> None:
    page.wait_for_function(
        "(n) => Number(document.querySelector('#image-canvas').dataset.drawn) > n", arg=count_before
    )


def drawn_count(page: Any) -> int:
    return int(page.get_attribute("#image-canvas", "data-drawn"))


# ±1 of image resampling between two screenshots, well below a drawn outline or fill.
CHANGED_LEVELS = 16
# By default nothing is drawn over the image; with ellipses shown (C, or a gallery scene whose telling
# view they are) they may cover at most this fraction of the image's pixels.
MAX_ELLIPSE_COVERAGE = 0.35


def overlay_coverage(page: Any) -> float:
    """Fraction of the image's on-screen pixels changed by what is drawn over it (ellipses, halos,
    markers, values, scale bar, readout): screenshots of the image with those layers shown and hidden."""
    image = page.locator("#image-canvas").bounding_box()
    view = page.locator("#viewport").bounding_box()
    x0, y0 = max(image["x"], view["x"]), max(image["y"], view["y"])
    x1 = min(image["x"] + image["width"], view["x"] + view["width"])
    y1 = min(image["y"] + image["height"], view["y"] + view["height"])
    clip = {"x": x0, "y": y0, "width": x1 - x0, "height": y1 - y0}
    layers = "#ellipse-overlay, #ellipse-halo, #marker-overlay, #value-canvas, #scale-bar, #hover-readout"

    def shot() -> np.ndarray:
        return np.asarray(Image.open(io.BytesIO(page.screenshot(clip=clip))).convert("RGB"), int)

    shown = shot()
    page.evaluate(
        f"() => document.querySelectorAll('{layers}').forEach((e) => (e.style.visibility = 'hidden'))"
    )
    hidden = shot()
    page.evaluate(f"() => document.querySelectorAll('{layers}').forEach((e) => (e.style.visibility = ''))")
    return float((np.abs(shown - hidden).max(axis=2) > CHANGED_LEVELS).mean())


def assert_ellipses_inside_their_cells(page: Any) -> None:
    """With the auto scale every ellipse's ℓ₁ semi-axis is at most half the grid spacing (image px), and
    the ellipse layers clip to the image."""
    spacing = float(page.input_value("#ellipse-spacing"))
    radii = page.evaluate(
        "() => [...document.querySelectorAll('#ellipse-overlay ellipse')]"
        ".map((e) => Number(e.getAttribute('rx')))"
    )
    assert radii and max(radii) <= spacing / 2 + 1e-9, (spacing, max(radii))
    for layer in ("#ellipse-overlay", "#ellipse-halo"):
        assert (
            page.evaluate(f"() => getComputedStyle(document.querySelector('{layer}')).overflow") == "hidden"
        )
