"""Linear sRGB → CIELAB of ``hgcore.colour`` (its CIEDE2000 is tested against Sharma et al. in
``tests/regression/test_ciede2000.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from hgcore.colour import (
    D65_WHITE_XYZ,
    LINEAR_SRGB_TO_XYZ,
    XYZ_TO_LINEAR_SRGB,
    band_edges_xyz_weights,
    linear_srgb_to_lab,
)
from hgcore.optics.spectra import cie_cmf


def test_lab_of_white_grey_and_primaries() -> None:
    white = linear_srgb_to_lab(np.ones(3), white_level=1.0)
    np.testing.assert_allclose(white, [100.0, 0.0, 0.0], atol=1e-9)
    # 18% grey: L* = 116·0.18^{1/3} − 16 = 49.496 (neutral, so a* = b* = 0); the white level rescales.
    np.testing.assert_allclose(linear_srgb_to_lab(np.full(3, 0.18), 1.0), [49.4961, 0.0, 0.0], atol=1e-3)
    np.testing.assert_allclose(linear_srgb_to_lab(np.full(3, 0.9), 5.0), [49.4961, 0.0, 0.0], atol=1e-3)
    # sRGB red primary: L* 53.24, a* 80.09, b* 67.20 (well-known values for the IEC matrix, ±0.1).
    np.testing.assert_allclose(
        linear_srgb_to_lab(np.array([1.0, 0.0, 0.0]), 1.0), [53.24, 80.09, 67.20], atol=0.15
    )


def test_srgb_matrices_are_the_iec_pair_at_full_precision() -> None:
    """IEC 61966-2-1 prints the forward matrix to 4 decimals; ours, computed from the primaries and the
    white point, rounds to exactly those digits, is the exact inverse of its partner (float64, 1e-15),
    and maps white (1, 1, 1) to the D65 white point with Y = 1."""
    printed = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    np.testing.assert_array_equal(np.round(LINEAR_SRGB_TO_XYZ, 4), printed)
    np.testing.assert_allclose(XYZ_TO_LINEAR_SRGB @ LINEAR_SRGB_TO_XYZ, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(LINEAR_SRGB_TO_XYZ @ np.ones(3), D65_WHITE_XYZ, rtol=1e-15)
    assert D65_WHITE_XYZ[1] == 1.0


@pytest.mark.parametrize("bands", [4, 16, 32, 64, 7])
def test_band_weights_cover_the_whole_range(bands: int) -> None:
    # The bands' ∫ x̄, ȳ, z̄ add up to the integrals over the film's range for any band width: bands of
    # 12.5 nm (32 over 380–780 nm) lost their last 0.5 nm each (−4 % of Y) until the grids ended on the edge.
    grid = np.linspace(380.0, 780.0, 4001)
    whole = np.trapezoid(cie_cmf(grid), grid, axis=0)
    weights = band_edges_xyz_weights(np.linspace(380.0, 780.0, bands + 1))
    # ≤ 1e-4: trapezoids over the 1 nm table on nodes that do not fall on its kinks (7 bands: 4.2e-5)
    np.testing.assert_allclose(weights.sum(axis=0), whole, rtol=1e-4)
