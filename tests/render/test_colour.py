"""CIEDE2000 against the supplementary test data of Sharma, Wu & Dalal (2005), and the Lab conversion."""

from __future__ import annotations

import numpy as np

from tests.render.colour import ciede2000, linear_srgb_to_lab

# (L1, a1, b1, L2, a2, b2, ΔE00) rows of Sharma et al.'s Table 1 (pairs 1, 2, 3, 7, 13, 17, 20, 25, 30, 34),
# covering the hue wrap-around, achromatic colours and the blue-region rotation term.
SHARMA_PAIRS = np.array(
    [
        [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
        [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
        [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
        [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
        [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
        [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
        [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
        [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
    ]
)


def test_ciede2000_reproduces_sharma_test_data() -> None:
    # The published values are rounded to 4 decimals: agreement to 1e-4 is the tolerance.
    computed = ciede2000(SHARMA_PAIRS[:, 0:3], SHARMA_PAIRS[:, 3:6])
    np.testing.assert_allclose(computed, SHARMA_PAIRS[:, 6], atol=1e-4)
    # Symmetric in its arguments (the formula uses only differences and means).
    np.testing.assert_allclose(ciede2000(SHARMA_PAIRS[:, 3:6], SHARMA_PAIRS[:, 0:3]), computed, atol=1e-12)


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
