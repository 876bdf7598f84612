"""A film of one pixel renders (a pass of one lane used to break Dr.Jit's loop recording) and estimates the
same quantity as a larger film: a pixel's box footprint covering the whole film, its value is the mean of
the 4×4 film's pixels (both unbiased; compared within their combined standard error)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.support.reference import hg_band_means
from tests.support.scenes import example

SPP = 256
BANDS = 4
Z_LIMIT = 4.0  # per band, 4 bands: a false failure below 3e-4


def test_one_pixel_film_matches_the_mean_of_a_larger_film(tmp_path: Path) -> None:
    one = hg_band_means(example("cornell_box", width=1, height=1, spp=SPP, bands=BANDS), tmp_path / "1", 3)
    grid = hg_band_means(example("cornell_box", width=4, height=4, spp=SPP, bands=BANDS), tmp_path / "4", 5)
    assert np.all(one.mean > 0) and np.all(np.isfinite(one.mean))
    z_scores = (one.mean - grid.mean) / np.hypot(one.standard_error, grid.standard_error)
    print("1×1", one.mean, "4×4", grid.mean, "z", np.round(z_scores, 2))
    assert np.all(np.abs(z_scores) <= Z_LIMIT), f"z = {np.round(z_scores, 2)}"
