"""Fresnel coefficients against closed forms (normal incidence, Brewster, TIR, energy, Stokes relations).

All checks are exact identities of the Fresnel equations, so the tolerance is float64 round-off
(a few ulp times the handful of operations involved): 1e-12 absolute.
"""

from __future__ import annotations

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import (
    fresnel_dielectric,
    fresnel_reflectance,
    interface_amplitudes,
    normal_factor,
)

ROUND_OFF = 1e-12


def _complex(pair: ComplexPair) -> np.ndarray:
    return np.asarray(pair.re) + 1j * np.asarray(pair.im)


@pytest.mark.parametrize("eta", [1.33, 1.5, 1.9, 2.4])
def test_normal_incidence_dielectric(eta: float) -> None:
    reflectance = fresnel_reflectance(np.array([1.0]), eta, NUMPY)
    assert reflectance[0] == pytest.approx(((eta - 1.0) / (eta + 1.0)) ** 2, abs=ROUND_OFF)


def test_normal_incidence_conductor() -> None:
    n, kappa = 0.2, 3.4
    reflectance = fresnel_reflectance(np.array([1.0]), ComplexPair(n, kappa), NUMPY)
    expected = ((n - 1.0) ** 2 + kappa**2) / ((n + 1.0) ** 2 + kappa**2)
    assert reflectance[0] == pytest.approx(expected, abs=ROUND_OFF)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.0])
def test_brewster_angle_zeroes_p(eta: float) -> None:
    theta_brewster = np.arctan(eta)
    cos_i = np.array([np.cos(theta_brewster)])
    invariant_sq = 1.0 - cos_i**2
    amplitudes = interface_amplitudes(
        1.0, ComplexPair.real(cos_i), eta, normal_factor(eta, invariant_sq, NUMPY)
    )
    assert amplitudes.r_p.abs2()[0] < ROUND_OFF
    assert amplitudes.r_s.abs2()[0] > 0.01


def test_total_internal_reflection() -> None:
    eta = 1.0 / 1.5  # glass → air
    critical_cos = np.sqrt(1.0 - eta**2)
    beyond = np.linspace(0.01, critical_cos * 0.999, 20)  # grazing side of the critical angle
    before = np.linspace(critical_cos * 1.001, 1.0, 20)
    reflectance_beyond, cos_t_beyond = fresnel_dielectric(beyond, eta, NUMPY)
    reflectance_before, cos_t_before = fresnel_dielectric(before, eta, NUMPY)
    np.testing.assert_allclose(reflectance_beyond, 1.0, atol=ROUND_OFF)
    np.testing.assert_allclose(cos_t_beyond, 0.0, atol=0.0)
    assert np.all(reflectance_before < 1.0) and np.all(cos_t_before > 0.0)


@pytest.mark.parametrize("eta", [1.0 / 1.5, 1.33, 1.5, 2.4])
def test_energy_conservation_dielectric(eta: float) -> None:
    """R + T = 1 per polarisation with T = (n_t cos θ_t)/(n_i cos θ_i)·|t|² (Hecht eq. 4.60)."""
    cos_i = np.linspace(0.05, 1.0, 40)
    invariant_sq = 1.0 - cos_i**2
    q_i = ComplexPair.real(cos_i)
    q_t = normal_factor(eta, invariant_sq, NUMPY)
    propagating = invariant_sq < eta**2
    amplitudes = interface_amplitudes(1.0, q_i, eta, q_t)
    for r, t in ((amplitudes.r_s, amplitudes.t_s), (amplitudes.r_p, amplitudes.t_p)):
        transmittance = np.where(propagating, np.asarray(q_t.re) / cos_i * t.abs2(), 0.0)
        np.testing.assert_allclose(r.abs2() + transmittance, 1.0, atol=ROUND_OFF)


def test_stokes_relations_complex_media() -> None:
    """r_ti = −r_it and t_it t_ti = 1 − r_it² for a film (1.45) on gold-like η = 0.3 + 2.9i."""
    cos_i = np.linspace(0.1, 1.0, 10)
    invariant_sq = 1.0 - cos_i**2
    eta_i, eta_t = ComplexPair(1.45, 0.0), ComplexPair(0.3, 2.9)
    q_i = normal_factor(eta_i, invariant_sq, NUMPY)
    q_t = normal_factor(eta_t, invariant_sq, NUMPY)
    forward = interface_amplitudes(eta_i, q_i, eta_t, q_t)
    backward = interface_amplitudes(eta_t, q_t, eta_i, q_i)
    for r_f, r_b, t_f, t_b in (
        (forward.r_s, backward.r_s, forward.t_s, backward.t_s),
        (forward.r_p, backward.r_p, forward.t_p, backward.t_p),
    ):
        np.testing.assert_allclose(_complex(r_b), -_complex(r_f), atol=ROUND_OFF)
        np.testing.assert_allclose(_complex(t_f) * _complex(t_b), 1.0 - _complex(r_f) ** 2, atol=ROUND_OFF)


def test_conductor_oblique_matches_complex_reference() -> None:
    """Against an independent numpy-complex evaluation of Born & Wolf's formulas via Snell's complex angle."""
    cos_i = np.linspace(0.02, 1.0, 50)
    eta = 0.13 + 3.3j  # silver near 600 nm
    sin_i = np.sqrt(1.0 - cos_i**2)
    cos_t = np.sqrt(1.0 - (sin_i / eta) ** 2 + 0j)
    r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    r_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    expected = 0.5 * (abs(r_s) ** 2 + abs(r_p) ** 2)
    reflectance = fresnel_reflectance(cos_i, ComplexPair(eta.real, eta.imag), NUMPY)
    np.testing.assert_allclose(reflectance, expected, atol=ROUND_OFF)


def test_complex_pair_sqrt_principal_branch() -> None:
    values = np.array([4.0 + 0j, -4.0 + 0j, 3.0 + 4.0j, 3.0 - 4.0j, -1.0 - 1e-3j, 1e-9 + 2.0j])
    root = ComplexPair(values.real, values.imag).sqrt(NUMPY)
    np.testing.assert_allclose(_complex(root), np.sqrt(values), atol=ROUND_OFF)
