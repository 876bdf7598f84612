"""Spectra and colorimetry: Planck against Wien and Stefan–Boltzmann, CIE tables against published values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize

from hgcore.colour import xyz_to_linear_srgb
from hgcore.optics.spectra import (
    ILLUMINANTS,
    cie_cmf,
    cie_illuminant,
    planck_radiance,
    spectrum_to_xyz,
    spectrum_values,
)

WIEN_B_M_K = 2.897771955e-3  # CODATA 2018
STEFAN_BOLTZMANN_W_M2_K4 = 5.670374419e-8  # CODATA 2018


@pytest.mark.parametrize("temperature_k", [2700.0, 5778.0, 6500.0])
def test_planck_peak_obeys_wien(temperature_k: float) -> None:
    """Brent search for the maximum; its tolerance (1e-10 relative) is far below the 1e-4 relative check."""
    peak_nm = WIEN_B_M_K / temperature_k * 1e9
    result = optimize.minimize_scalar(
        lambda w: -float(planck_radiance(w, temperature_k)),
        bracket=(0.5 * peak_nm, peak_nm, 2 * peak_nm),
        tol=1e-10,
    )
    assert result.x == pytest.approx(peak_nm, rel=1e-4)


@pytest.mark.parametrize("temperature_k", [1500.0, 3000.0, 6500.0])
def test_planck_integrates_to_stefan_boltzmann(temperature_k: float) -> None:
    """π ∫ B_λ dλ = σ T⁴ (Lambertian exitance). Adaptive quadrature in log λ over 10 nm – 10 m: its error
    estimate is < 1e-9 relative and the Rayleigh–Jeans tail beyond 10 m, 2ckT/(3L³), is < 1e-16 relative."""

    def integrand(log_nm: float) -> float:
        wavelength_nm = math.exp(log_nm)
        return float(planck_radiance(wavelength_nm, temperature_k)) * wavelength_nm

    total, error = integrate.quad(integrand, math.log(10.0), math.log(1e10), epsrel=1e-11, limit=400)
    assert error < 1e-9 * total
    assert math.pi * total == pytest.approx(STEFAN_BOLTZMANN_W_M2_K4 * temperature_k**4, rel=1e-8)


def test_d65_normalisation_and_known_values() -> None:
    assert cie_illuminant("d65", 560.0) == pytest.approx(100.0, abs=1e-9)
    # CIE 15:2004 Table T.1: D65 = 117.812 at 460 nm, 82.7549 at 400 nm, 49.9755 at 380 nm.
    assert cie_illuminant("D65", 460.0) == pytest.approx(117.812, abs=1e-3)
    assert cie_illuminant("d65", 400.0) == pytest.approx(82.7549, abs=1e-3)
    assert cie_illuminant("d65", 380.0) == pytest.approx(49.9755, abs=1e-3)


def test_all_fluorescent_illuminants_load() -> None:
    grid = np.arange(380.0, 781.0, 5.0)
    for name in ILLUMINANTS[1:]:
        values = cie_illuminant(name, grid)
        assert values.shape == grid.shape and np.all(values > 0.0)
    # F2 (cool white) has the 435.8 nm and 546.1 nm mercury lines; its 435 nm sample exceeds its 430 nm one.
    assert cie_illuminant("FL2", 435.0) > 2 * cie_illuminant("f2", 430.0)


def test_cmf_integral_and_white_point() -> None:
    """∫ ȳ dλ over 360–830 nm at 1 nm = 106.856895 (CIE 15:2004); equal-energy white has x = y = 1/3 up to
    the table's rounding (≈ 1e-4); D65 has chromaticity (0.31272, 0.32903)."""
    grid = np.arange(360.0, 831.0, 1.0)
    xyz_e = spectrum_to_xyz(grid, spectrum_values("equal_energy", grid))
    assert xyz_e[1] == pytest.approx(106.856895, abs=2e-3)
    chroma_e = xyz_e / xyz_e.sum()
    np.testing.assert_allclose(chroma_e[:2], 1.0 / 3.0, atol=3e-4)
    grid5 = np.arange(380.0, 781.0, 5.0)
    xyz_d65 = spectrum_to_xyz(grid5, spectrum_values("d65", grid5))
    np.testing.assert_allclose((xyz_d65 / xyz_d65.sum())[:2], (0.31272, 0.32903), atol=3e-4)


def test_srgb_matrix_maps_d65_white_to_grey() -> None:
    """IEC 61966-2-1: XYZ of the D65 white (0.9505, 1, 1.089) maps to R = G = B = 1 within the matrix's 4
    decimals (≈ 1e-3)."""
    rgb = xyz_to_linear_srgb(np.array([0.95047, 1.0, 1.08883]))
    np.testing.assert_allclose(rgb, 1.0, atol=2e-3)
    assert cie_cmf(np.array([555.0]))[0, 1] == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: planck_radiance(500.0, -1.0), "temperature_k"),
        (lambda: planck_radiance(-5.0, 3000.0), "wavelength_nm"),
        (lambda: spectrum_values("blackbody", 500.0), "temperature_k"),
        (lambda: spectrum_values("sunlight", 500.0), "kind"),
        (lambda: spectrum_values("d65", 500.0, temperature_k=3.0), "temperature_k"),
        (lambda: spectrum_values("d65", 500.0, scale=-1.0), "scale"),
        (lambda: cie_illuminant("a", 500.0), "name"),
        (lambda: xyz_to_linear_srgb(np.ones(2)), "xyz"),
    ],
)
def test_invalid_input_names_parameter(call, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        call()
