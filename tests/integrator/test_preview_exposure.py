"""preview.png's exposure: saturated highlights keep their colour (hgcore.imaging.preview_exposure_ev)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from hgcore.artifacts.images import preview_png
from hgcore.imaging import PREVIEW_CLIPPED_FRACTION, auto_exposure_ev, preview_exposure_ev


def test_a_saturated_highlight_is_not_clipped_to_white() -> None:
    """A dim grey scene with a pure-red highlight on 5 % of the pixels: luminance p99 (the viewer's auto
    exposure) lands on the red pixels' luminance 0.2126·R and clips R far above 1; the preview rule maps the
    red channel to 1, so the highlight stays red and unclipped."""
    rgb = np.full((100, 100, 3), 0.01)
    rgb[:5, :, :] = [1.0, 0.0, 0.0]
    assert auto_exposure_ev(rgb) == pytest.approx(-np.log2(0.2126))  # R × 4.7: clipped
    assert preview_exposure_ev(rgb) == pytest.approx(0.0)
    pixels = np.asarray(Image.open(io.BytesIO(preview_png(rgb))))
    assert tuple(pixels[0, 0]) == (255, 0, 0)
    assert tuple(pixels[50, 50]) == (25, 25, 25)  # 0.01 linear → sRGB 25


def test_at_most_the_stated_fraction_of_pixels_clips() -> None:
    rng = np.random.default_rng(1)
    rgb = rng.lognormal(0.0, 2.0, size=(200, 300, 3))
    exposed = rgb * 2.0 ** preview_exposure_ev(rgb)
    clipped = np.mean(exposed.max(axis=-1) > 1.0 + 1e-9)
    assert clipped <= PREVIEW_CLIPPED_FRACTION
    assert clipped >= PREVIEW_CLIPPED_FRACTION / 2  # and the image is not needlessly dark


def test_black_image_has_zero_exposure() -> None:
    assert preview_exposure_ev(np.zeros((4, 4, 3))) == 0.0
