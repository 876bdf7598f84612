"""Spectral refractive indices: tabulated metals against Mitsuba's source tables, Sellmeier glasses against
datasheet values. Interpolation is linear, so at a tabulated wavelength it returns the table value exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hgcore.optics.ior as ior_module
from hgcore.optics.ior import ior_table, material_range_nm, spectral_ior

MITSUBA_IOR_DIR = Path(__file__).resolve().parents[2] / ".venv/lib/python3.11/site-packages/mitsuba/data/ior"


@pytest.mark.parametrize(
    ("material", "symbol"), [("silver", "Ag"), ("gold", "Au"), ("copper", "Cu"), ("aluminium", "Al")]
)
def test_metal_spot_values_match_source_tables(material: str, symbol: str) -> None:
    if not MITSUBA_IOR_DIR.is_dir():
        pytest.skip("Mitsuba's data/ior tables are not installed in .venv")
    eta = np.loadtxt(MITSUBA_IOR_DIR / f"{symbol}.eta.spd")
    kappa = np.loadtxt(MITSUBA_IOR_DIR / f"{symbol}.k.spd")
    rows = np.arange(0, eta.shape[0], 7)
    n, k = spectral_ior(symbol, eta[rows, 0])
    np.testing.assert_allclose(n, eta[rows, 1], atol=1e-6)
    np.testing.assert_allclose(k, kappa[rows, 1], atol=1e-6)


def test_metal_interpolates_between_samples() -> None:
    table_nm, table_n, table_kappa = ior_module.metal_table("gold")
    middle = 0.5 * (table_nm[10] + table_nm[11])
    n, kappa = spectral_ior("gold", middle)
    assert n == pytest.approx(0.5 * (table_n[10] + table_n[11]), abs=1e-12)
    assert kappa == pytest.approx(0.5 * (table_kappa[10] + table_kappa[11]), abs=1e-12)


@pytest.mark.parametrize(
    ("material", "wavelength_nm", "expected", "tolerance"),
    [
        # Schott N-BK7 datasheet: n_d = 1.51680 (587.56 nm), n_F = 1.52238 (486.13), n_C = 1.51432 (656.27);
        # the Sellmeier fit reproduces the catalogue to its 5 decimals.
        ("bk7", 587.56, 1.51680, 2e-5),
        ("bk7", 486.13, 1.52238, 2e-5),
        ("bk7", 656.27, 1.51432, 2e-5),
        # Malitson (1965) Table: fused silica n = 1.45846 at 587.56 nm, 1.46313 at 486.13 nm.
        ("fused_silica", 587.56, 1.45846, 2e-5),
        ("fused_silica", 486.13, 1.46313, 2e-5),
        # Water, 20 °C: n_D = 1.33299 (CRC); Daimon & Masumura's fit lies within 5e-4 of it.
        ("water", 589.29, 1.33299, 5e-4),
    ],
)
def test_sellmeier_glasses(material: str, wavelength_nm: float, expected: float, tolerance: float) -> None:
    n, kappa = spectral_ior(material, wavelength_nm)
    assert n == pytest.approx(expected, abs=tolerance)
    assert kappa == 0.0


def test_aliases_and_range() -> None:
    assert material_range_nm("Ag")[0] == pytest.approx(298.757, abs=1e-3)
    assert spectral_ior("N-BK7", 500.0)[0] == spectral_ior("bk7", 500.0)[0]


@pytest.mark.parametrize(
    ("material", "wavelength", "field"),
    [
        ("unobtainium", 500.0, "material"),
        ("gold", 150.0, "wavelength_nm"),
        ("gold", 2600.0, "wavelength_nm"),
        ("gold", 1000.0, "wavelength_nm"),  # inside 200–2500 nm but beyond Palik's table here
        ("water", float("nan"), "wavelength_nm"),
    ],
)
def test_invalid_queries_name_parameter(material: str, wavelength: float, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        spectral_ior(material, wavelength)


def test_ior_table_holds_end_values_beyond_data() -> None:
    grid = np.arange(200.0, 2501.0, 5.0)
    table = ior_table("silver", grid)
    first_n, first_kappa = spectral_ior("silver", material_range_nm("silver")[0])
    assert table.shape == (grid.size, 3)
    assert table[0, 1] == pytest.approx(first_n) and table[0, 2] == pytest.approx(first_kappa)
    inside = (grid > 300) & (grid < 880)
    np.testing.assert_allclose(table[inside, 1], spectral_ior("silver", grid[inside])[0])
    with pytest.raises(ValueError, match=r"^grid_nm"):
        ior_table("silver", np.array([500.0, 400.0]))
    with pytest.raises(ValueError, match=r"^grid_nm"):
        ior_table("silver", np.array([100.0, 400.0]))
