"""CIEDE2000 and the spectrum → XYZ → CIELAB chain of ``hgcore.colour`` against published values.

The 34 pairs of Sharma, Wu & Dalal (2005), Table 1 (``data/sharma2005_ciede2000.csv``, see its header) are
published to 4 decimals, so each computed ΔE₀₀ must agree to half a unit of the last digit (5e-5); float64
rounding adds < 1e-12.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hgcore.colour import D65_WHITE_XYZ, bands_to_xyz, ciede2000, xyz_to_lab
from hgcore.optics.spectra import cie_cmf

DATA_FILE = Path(__file__).parent / "data" / "sharma2005_ciede2000.csv"


def sharma_table() -> np.ndarray:
    return np.loadtxt(DATA_FILE, delimiter=",", comments="#", skiprows=6)


def test_table_has_the_34_published_pairs() -> None:
    table = sharma_table()
    assert table.shape == (34, 8)
    np.testing.assert_array_equal(table[:, 0], np.arange(1, 35))


def test_ciede2000_matches_sharma_2005_to_four_decimals() -> None:
    table = sharma_table()
    delta_e = ciede2000(table[:, 1:4], table[:, 4:7])
    np.testing.assert_allclose(delta_e, table[:, 7], rtol=0.0, atol=5e-5)
    # Symmetric in its arguments (means and squared differences only).
    np.testing.assert_allclose(ciede2000(table[:, 4:7], table[:, 1:4]), delta_e, rtol=0.0, atol=1e-12)


def test_lab_of_white_and_of_a_band_spectrum() -> None:
    np.testing.assert_allclose(xyz_to_lab(D65_WHITE_XYZ * 3.0, D65_WHITE_XYZ * 3.0), [100.0, 0.0, 0.0])
    # A flat spectrum of 1 over 16 bands of 380-780 nm: XYZ = ∫ cmf dλ over that range (trapezoid on a
    # 1 nm grid: the CMF table is itself 1 nm, so both integrals agree to rounding, < 1e-9 relative).
    centers_nm = 380.0 + 25.0 * (np.arange(16) + 0.5)
    grid_nm = np.arange(380.0, 781.0)
    expected = np.trapezoid(cie_cmf(grid_nm), grid_nm, axis=0)
    np.testing.assert_allclose(bands_to_xyz(np.ones(16), centers_nm), expected, rtol=1e-9)


def test_bad_inputs_name_the_parameter() -> None:
    with pytest.raises(ValueError, match=r"^lab_sample: "):
        ciede2000(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"^white_xyz: "):
        xyz_to_lab(np.ones(3), np.array([1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match=r"^band_centers_nm: "):
        bands_to_xyz(np.ones(2), np.array([500.0, 400.0]))
