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


def test_non_finite_pixels_neither_move_the_exposure_nor_warn() -> None:
    """A NaN and an inf pixel (a renderer sample gone wrong) in the lognormal image: both exposure rules
    give the EV of the finite pixels alone (before, the NaN made every quantile NaN and the preview fell
    back to 0 EV), and the preview shows the NaN pixel black (as the viewer does) without a cast warning."""
    import warnings

    rng = np.random.default_rng(2)
    rgb = rng.lognormal(0.0, 2.0, size=(40, 50, 3))
    finite_preview, finite_auto = preview_exposure_ev(rgb), auto_exposure_ev(rgb)
    broken = np.concatenate([rgb.reshape(-1, 3), [[np.nan, 0.5, 0.5], [np.inf, np.inf, np.inf]]])[None]
    assert preview_exposure_ev(broken) == pytest.approx(
        -np.log2(np.quantile(rgb.max(axis=-1), 1 - PREVIEW_CLIPPED_FRACTION))
    )
    assert auto_exposure_ev(broken) == pytest.approx(finite_auto)
    assert finite_preview != 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pixels = np.asarray(Image.open(io.BytesIO(preview_png(broken))))
    assert pixels[0, -2][0] == 0
    assert tuple(pixels[0, -1]) == (255, 255, 255)
