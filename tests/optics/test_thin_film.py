"""Thin-film reflectance (Eq. 18 generalised to P beams) against the Airy and two-beam closed forms.

The reference values are computed here independently with NumPy complex arithmetic (textbook Fresnel
formulas, Born & Wolf §1.6 / §7.6), not with ``hgcore.optics.fresnel``.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.coherence import degree_of_coherence
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.sources import cylinder_covariance_components
from hgcore.optics.thin_film import (
    bounded_reflectance,
    combine_reflectance_terms,
    film_amplitudes,
    film_reflectance_terms,
    film_shear,
    gaussian_visibilities,
    reflectance_terms,
    thin_film_reflectance,
    transmission_terms,
    validate_thin_film,
)

ROUND_OFF = 1e-12


def _film_fresnel(cos_i: np.ndarray, n0: float, nf: float, eta_s: complex, polarisation: str):
    """(r01, r12, t01 t10, q1) of exterior | film | substrate, numpy complex, Hecht's conventions."""
    sin_sq = (n0**2) * (1.0 - cos_i**2)
    q0 = n0 * cos_i + 0j
    q1 = np.sqrt(nf**2 - sin_sq + 0j)
    q2 = np.sqrt(eta_s**2 - sin_sq + 0j)
    if polarisation == "s":
        r01 = (q0 - q1) / (q0 + q1)
        r12 = (q1 - q2) / (q1 + q2)
    else:
        r01 = (nf**2 * q0 - n0**2 * q1) / (nf**2 * q0 + n0**2 * q1)
        r12 = (eta_s**2 * q1 - nf**2 * q2) / (eta_s**2 * q1 + nf**2 * q2)
    return r01, r12, 1.0 - r01**2, q1


def _airy(cos_i, wavelength_m, thickness_m, n0, nf, eta_s):
    total = 0.0
    for polarisation in ("s", "p"):
        r01, r12, _, q1 = _film_fresnel(cos_i, n0, nf, eta_s, polarisation)
        phase = np.exp(2j * (2 * np.pi / wavelength_m) * q1 * thickness_m)
        total = total + 0.5 * np.abs((r01 + r12 * phase) / (1.0 + r01 * r12 * phase)) ** 2
    return total


def _reflectance(cos_i, wavelength_m, thickness_m, n0, nf, eta_s, visibilities):
    substrate = ComplexPair(np.full_like(cos_i, eta_s.real), np.full_like(cos_i, eta_s.imag))
    return thin_film_reflectance(cos_i, wavelength_m, thickness_m, nf, substrate, n0, visibilities, NUMPY)


CASES = [
    # (n0, nf, eta_s): a film on gold-like metal, on silver, and on a denser glass
    (1.0, 1.38, 0.27 + 2.9j),
    (1.0, 1.6, 0.13 + 3.4j),
    (1.0, 1.45, 1.9 + 0j),
]


@pytest.mark.parametrize(("n0", "nf", "eta_s"), CASES)
def test_fully_coherent_limit_is_airy(n0: float, nf: float, eta_s: complex) -> None:
    """V_d = 1 and P beams: the partial sum of the Airy series.

    Truncation: the neglected tail Σ_{p≥P} a_p = a_P/(1 − ρ), ρ = r10 r12 e^{iδ}, has modulus
    ε ≤ |t01 t10 r12| |ρ|^{P−1}/(1 − |ρ|); then |R_P − R| ≤ 2|r|ε + ε² per polarisation.
    """
    beams = 40
    cos_i = np.linspace(0.15, 1.0, 12)
    wavelength_m, thickness_m = 560e-9, 420e-9
    result = _reflectance(cos_i, wavelength_m, thickness_m, n0, nf, eta_s, [1.0] * (beams - 1))
    expected = _airy(cos_i, wavelength_m, thickness_m, n0, nf, eta_s)
    bound = np.zeros_like(cos_i)
    for polarisation in ("s", "p"):
        r01, r12, t_product, _ = _film_fresnel(cos_i, n0, nf, eta_s, polarisation)
        rho = np.abs(r01 * r12)
        epsilon = np.abs(t_product * r12) * rho ** (beams - 1) / (1.0 - rho)
        bound += 0.5 * (2.0 * 1.0 * epsilon + epsilon**2)
    assert np.all(np.abs(result - expected) <= bound + ROUND_OFF)


def _local_extrema(values: np.ndarray) -> np.ndarray:
    slope = np.sign(np.diff(values))
    return np.nonzero(slope[1:] != slope[:-1])[0] + 1


@pytest.mark.parametrize("nf", [1.33, 1.45, 1.7])
@pytest.mark.parametrize("eta_s", [0.27 + 2.9j, 0.13 + 3.4j, 1.2 + 7.0j])
def test_fringe_extrema_on_metal_follow_fresnel_phase(nf: float, eta_s: complex) -> None:
    """Normal incidence on a metal: extrema where 2k n_f τ + arg r12 − arg r01 = mπ.

    R ∝ (A + B cos ψ)/(C + D cos ψ) with ψ = δ + arg r12 − arg r01 (r01 real), monotone in cos ψ, so its
    extrema in τ sit exactly at ψ = mπ; they are located on a grid of step h, so |τ_found − τ_m| ≤ h.
    """
    wavelength_m = 550e-9
    step_m = 0.05e-9
    thickness_m = np.arange(50e-9, 900e-9, step_m)
    cos_i = np.ones_like(thickness_m)
    reflectance = _reflectance(cos_i, wavelength_m, thickness_m, 1.0, nf, eta_s, [1.0] * 60)
    found = thickness_m[_local_extrema(reflectance)]
    r01, r12, _, _ = _film_fresnel(np.ones(1), 1.0, nf, eta_s, "s")
    offset = np.angle(r12[0]) - np.angle(r01[0])
    k_film = 2.0 * (2.0 * math.pi / wavelength_m) * nf
    m = np.arange(-4, 20)
    predicted = (m * math.pi - offset) / k_film
    predicted = predicted[(predicted > thickness_m[1]) & (predicted < thickness_m[-2])]
    assert len(found) == len(predicted)
    np.testing.assert_allclose(np.sort(found), np.sort(predicted), atol=step_m)


@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 40.0])
@pytest.mark.parametrize("nf", [1.38, 1.5])
def test_fringe_extrema_dielectric_stack_oblique(theta_deg: float, nf: float) -> None:
    """Film between air and a denser glass (n_s = 1.9), below both Brewster angles: extrema where
    2 n_f τ cos θ_t = m λ/2 (arg r12 − arg r01 = 0 for s and p alike); grid tolerance as above."""
    wavelength_m, eta_s = 600e-9, 1.9 + 0j
    step_m = 0.05e-9
    thickness_m = np.arange(40e-9, 1000e-9, step_m)
    cos_i = np.full_like(thickness_m, math.cos(math.radians(theta_deg)))
    reflectance = _reflectance(cos_i, wavelength_m, thickness_m, 1.0, nf, eta_s, [1.0] * 60)
    found = thickness_m[_local_extrema(reflectance)]
    cos_t = math.sqrt(1.0 - (math.sin(math.radians(theta_deg)) / nf) ** 2)
    predicted = np.arange(1, 40) * wavelength_m / (4.0 * nf * cos_t)
    predicted = predicted[(predicted > thickness_m[1]) & (predicted < thickness_m[-2])]
    assert len(found) == len(predicted)
    np.testing.assert_allclose(found, predicted, atol=step_m)


@pytest.mark.parametrize(("n0", "nf", "eta_s"), CASES)
def test_incoherent_limit_is_intensity_sum(n0: float, nf: float, eta_s: complex) -> None:
    """V_d = 0: Σ_p |a_p|² = |r01|² + |t01 t10 r12|² Σ_{p<P} |r10 r12|^{2(p−1)} (a geometric sum)."""
    beams = 12
    cos_i = np.linspace(0.2, 1.0, 9)
    result = _reflectance(cos_i, 500e-9, 700e-9, n0, nf, eta_s, [0.0] * (beams - 1))
    expected = 0.0
    for polarisation in ("s", "p"):
        r01, r12, t_product, _ = _film_fresnel(cos_i, n0, nf, eta_s, polarisation)
        ratio = np.abs(r01 * r12) ** 2
        geometric = (1.0 - ratio ** (beams - 1)) / (1.0 - ratio)
        expected = expected + 0.5 * (np.abs(r01) ** 2 + np.abs(t_product * r12) ** 2 * geometric)
    np.testing.assert_allclose(result, expected, atol=ROUND_OFF)


def _transmitted_beams(cos_i, wavelength_m, thickness_m, n0, nf, n_s, polarisation, beams):
    """(power factor, transmitted amplitudes b_p = t01 t12 e^{iδ/2} (r10 r12 e^{iδ})^p) from the textbook
    interface formulas (E-field amplitudes: T = (n_s cos θ_s)/(n_0 cos θ_0)|t|² = (q_s/q_0)|t|² for s and
    p alike with Hecht's t_p)."""
    sin_sq = (n0**2) * (1.0 - cos_i**2)
    q0 = n0 * cos_i + 0j
    q1 = np.sqrt(nf**2 - sin_sq + 0j)
    q2 = np.sqrt(n_s**2 - sin_sq + 0j)
    if polarisation == "s":
        t01, t12 = 2 * q0 / (q0 + q1), 2 * q1 / (q1 + q2)
        r10, r12 = (q1 - q0) / (q0 + q1), (q1 - q2) / (q1 + q2)
        power = (q2 / q0).real
    else:
        t01 = 2 * n0 * nf * q0 / (nf**2 * q0 + n0**2 * q1)
        t12 = 2 * nf * n_s * q1 / (n_s**2 * q1 + nf**2 * q2)
        r10 = (n0**2 * q1 - nf**2 * q0) / (nf**2 * q0 + n0**2 * q1)
        r12 = (n_s**2 * q1 - nf**2 * q2) / (n_s**2 * q1 + nf**2 * q2)
        power = (q2 / q0).real
    phase = np.exp(1j * (2 * np.pi / wavelength_m) * q1 * thickness_m)
    first = t01 * t12 * phase
    bounce = r10 * r12 * phase**2
    return power, [first * bounce**p for p in range(beams)]


@pytest.mark.parametrize("theta_deg", [0.0, 35.0, 70.0])
@pytest.mark.parametrize(("nf", "n_s"), [(1.38, 1.52), (2.1, 1.5), (1.45, 1.9)])
def test_transmission_is_the_transmitted_beam_sum_and_conserves_energy(
    theta_deg: float, nf: float, n_s: float
) -> None:
    """T(V) = 1 − R(V) (``transmission_terms``) equals the transmitted beams' own sums: the Airy
    transmittance under full coherence and Σ_p |b_p|² incoherently (P = 60: the truncated tail is below
    |r10 r12|^{120} ≈ 1e-40 here), at several angles and thicknesses; R + T = 1 for every V."""
    cos_i = np.full(5, math.cos(math.radians(theta_deg)))
    thickness_m = np.array([80e-9, 233e-9, 420e-9, 615e-9, 1230e-9])
    wavelength_m, beams = 550e-9, 60
    substrate = ComplexPair(np.full(5, n_s), np.zeros(5))
    amplitudes = film_amplitudes(cos_i, wavelength_m, thickness_m, nf, substrate, 1.0, beams, NUMPY)
    t_terms = transmission_terms(reflectance_terms(amplitudes))
    coherent = incoherent = 0.0
    for polarisation in ("s", "p"):
        power, transmitted = _transmitted_beams(
            cos_i, wavelength_m, thickness_m, 1.0, nf, n_s, polarisation, beams
        )
        coherent = coherent + 0.5 * power * np.abs(sum(transmitted)) ** 2
        incoherent = incoherent + 0.5 * power * sum(np.abs(b) ** 2 for b in transmitted)
    np.testing.assert_allclose(combine_reflectance_terms(t_terms, [1.0] * (beams - 1)), coherent, atol=1e-9)
    np.testing.assert_allclose(combine_reflectance_terms(t_terms, [0.0] * (beams - 1)), incoherent, atol=1e-9)
    partial = gaussian_visibilities(np.full(5, 0.7), beams - 1, NUMPY)
    r_partial = combine_reflectance_terms(reflectance_terms(amplitudes), partial)
    np.testing.assert_allclose(r_partial + combine_reflectance_terms(t_terms, partial), 1.0, atol=1e-12)


def test_two_beam_is_eq18() -> None:
    """P = 2: R = I1 + I2 + 2√(I1 I2) V cos(δ + arg a1 − arg a0) per polarisation (Eq. 18), linear in V."""
    cos_i = np.linspace(0.3, 1.0, 7)
    wavelength_m, thickness_m, nf, eta_s = 633e-9, 1.23e-6, 1.5, 0.13 + 3.4j
    for visibility in (1.0, 0.6, 0.2, 0.0):
        result = _reflectance(cos_i, wavelength_m, thickness_m, 1.0, nf, eta_s, [visibility])
        expected = 0.0
        for polarisation in ("s", "p"):
            r01, r12, t_product, q1 = _film_fresnel(cos_i, 1.0, nf, eta_s, polarisation)
            a0 = r01
            a1 = t_product * r12 * np.exp(2j * (2 * np.pi / wavelength_m) * q1 * thickness_m)
            i1, i2 = np.abs(a0) ** 2, np.abs(a1) ** 2
            cosine = np.cos(np.angle(a1) - np.angle(a0))
            expected = expected + 0.5 * (i1 + i2 + 2.0 * np.sqrt(i1 * i2) * visibility * cosine)
        np.testing.assert_allclose(result, expected, atol=ROUND_OFF)


def transverse_shear(theta: float, thickness_m: np.ndarray, film_ior: float) -> np.ndarray:
    """|s_⊥| of ``film_shear`` for a film in the xy plane lit at θ in the xz plane: |s| cos θ (the shear lies
    along x, the transverse plane of the incident beam meets it at angle θ)."""
    k_hat = (math.sin(theta), 0.0, -math.cos(theta))
    shear = film_shear((0.0, 0.0, 1.0), k_hat, thickness_m, film_ior, 1.0, NUMPY)
    return np.hypot(shear[0], shear[2]) * math.cos(theta)


def _fringe_visibility(values: np.ndarray) -> float:
    return float((values.max() - values.min()) / (values.max() + values.min()))


def test_fringe_visibility_falls_as_source_grows() -> None:
    """Gaussian source of growing std σ at r = 0.6 m: V_1 = exp(−½ (k/r)² σ² ξ²), ξ = |s_⊥| the transverse
    film shear 2τ tan θ_t cos θ (``transverse_shear``); the fringe
    visibility over a thickness sweep decreases strictly and tends to 0 (the incoherent sum has no fringes
    beyond the slow variation of the Fresnel factors)."""
    wavelength_m, theta = 550e-9, math.radians(50.0)
    thickness_m = np.linspace(1.0e-6, 1.6e-6, 3001)
    cos_i = np.full_like(thickness_m, math.cos(theta))
    k_over_r = 2.0 * math.pi / wavelength_m / 0.6
    visibilities = []
    for source_sigma_m in (0.0, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32):
        separation_m = transverse_shear(theta, thickness_m, 1.5)
        first = np.exp(-0.5 * (k_over_r * source_sigma_m * separation_m) ** 2)
        reflectance = _reflectance(
            cos_i, wavelength_m, thickness_m, 1.0, 1.5, 0.13 + 3.4j, gaussian_visibilities(first, 8, NUMPY)
        )
        visibilities.append(_fringe_visibility(reflectance))
    assert all(later < earlier for earlier, later in itertools.pairwise(visibilities))
    # On silver the fringes are shallow (|r01| ≪ |r12|) even for a point source; at σ = 0.32 m, V_1 < 1e-4.
    assert visibilities[0] > 0.02 and visibilities[-1] < 0.01 * visibilities[0]


def test_gaussian_visibilities_are_powers() -> None:
    first = np.array([0.9, 0.5, 0.1])
    values = gaussian_visibilities(first, 5, NUMPY)
    for d, value in enumerate(values, start=1):
        np.testing.assert_allclose(value, first ** (d * d), rtol=1e-13)


def test_cylinder_source_gives_direction_dependent_visibility() -> None:
    """Fig. 7: a cylinder (L = 20 cm, R = 1 mm) 60 cm away seen side-on is a uniform strip with transverse
    variances (2R)²/12 across and L²/12 along its axis. A 1.23 µm film whose normal tilts (θ = 60°) towards
    the short-source axis sees coherent beams (ℓ ≈ 90 µm ≫ |s_⊥| ≈ 0.87 µm); tilted towards the long axis
    (ℓ ≈ 0.9 µm) V_1 ≤ 0.7 over the 1.1–1.4 µm sweep. With two dominant beams the fringe visibility is ∝ V_1,
    so the ratio of fringe visibilities is ≈ V_short/V_long ≥ 1/0.7 ≈ 1.43; we require 1.3 (measured 2.36)."""
    wavelength_m, distance_m = 550e-9, 0.6
    # Side-on cylinder along the transverse x axis: x = long source axis, y = across (short).
    sigma = cylinder_covariance_components(0.001, 0.2, (1.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    assert sigma[0] == pytest.approx(0.2**2 / 12.0) and sigma[2] == pytest.approx((2 * 0.001) ** 2 / 12.0)
    theta = math.radians(60.0)
    thickness_m = np.linspace(1.1e-6, 1.4e-6, 2001)
    cos_i = np.full_like(thickness_m, math.cos(theta))
    coefficients = {(0, 0): math.sqrt(math.pi)}  # 0th mode: μ = exp(−½ ξᵀMξ)
    fringe = {}
    for axis in ("long", "short"):
        transverse = transverse_shear(theta, thickness_m, 1.5)
        xi = (transverse, 0.0 * transverse) if axis == "long" else (0.0 * transverse, transverse)
        first = degree_of_coherence(xi, sigma, distance_m, wavelength_m, coefficients, NUMPY)
        visibilities = gaussian_visibilities(first, 6, NUMPY)
        reflectance = _reflectance(cos_i, wavelength_m, thickness_m, 1.0, 1.5, 0.13 + 3.4j, visibilities)
        fringe[axis] = _fringe_visibility(reflectance)
        if axis == "short":
            assert np.all(first > 0.99)
        else:
            assert np.all(first < 0.7)
    assert fringe["short"] > 1.3 * fringe["long"]


def test_validation_names_parameter() -> None:
    with pytest.raises(ValueError, match=r"^thickness_m"):
        validate_thin_film(-1e-9, 1.5, 1.0)
    with pytest.raises(ValueError, match=r"^film_ior"):
        validate_thin_film(1e-7, float("nan"), 1.0)
    with pytest.raises(ValueError, match=r"^exterior_ior"):
        validate_thin_film(1e-7, 1.5, 0.5)
    with pytest.raises(ValueError, match=r"^visibilities"):
        combine_reflectance_terms([0.5, 0.1, 0.01], [1.0])


SUBSTRATES = {"Ag": 0.13 + 3.4j, "Au": 0.27 + 2.9j, "glass": 1.5 + 0j, "dense glass": 1.9 + 0j}
GRAZING_COS = np.cos(np.radians(np.linspace(0.0, 89.9, 1000)))


def _all_beam_terms(substrate: complex, thickness_m: float, film_ior: float, beams: int) -> list[np.ndarray]:
    eta = ComplexPair(np.full_like(GRAZING_COS, substrate.real), np.full_like(GRAZING_COS, substrate.imag))
    return film_reflectance_terms(GRAZING_COS, 550e-9, thickness_m, film_ior, eta, 1.0, beams, NUMPY)


@pytest.mark.parametrize("substrate", list(SUBSTRATES))
@pytest.mark.parametrize("beams", [2, 3, 4, 7])
def test_every_beam_reflectance_is_bounded_at_every_angle(substrate: str, beams: int) -> None:
    """R ∈ [0, 1] and T = 1 − R ≥ 0 at 0°–89.9° for thicknesses 0.1–3 µm and Gaussian visibilities (module
    docstring "All beams"). The P-beam truncation this replaces exceeds 1 on silver near grazing
    incidence (7 beams: ≥ 1.05), so the check has power; the unclipped all-beam sum (P ≥ 3) is within the
    documented 2e-3 of [0, 1]; P = 2 is Eq. (18) itself, ≤ 1 on glass, above 1 on metals (the paper's
    equation, reproduced as published)."""
    for thickness_m in (0.1e-6, 0.4e-6, 1.23e-6, 3.0e-6):
        for film_ior in (1.38, 1.5, 2.1):
            terms = _all_beam_terms(SUBSTRATES[substrate], thickness_m, film_ior, beams)
            for first in (0.0, 0.3, 0.6, 0.9, 0.99, 1.0):
                visibilities = gaussian_visibilities(np.full_like(GRAZING_COS, first), beams - 1, NUMPY)
                raw = combine_reflectance_terms(terms, visibilities)
                if beams > 2:
                    assert raw.min() >= -1e-12 and raw.max() <= 1.0 + 2e-3, (thickness_m, film_ior, first)
                reflectance = bounded_reflectance(terms, visibilities, NUMPY)
                transmittance = bounded_reflectance(transmission_terms(terms), visibilities, NUMPY)
                assert reflectance.min() >= 0.0 and transmittance.min() >= 0.0
                if beams > 2 or substrate in ("glass", "dense glass"):
                    assert reflectance.max() <= 1.0
    if substrate == "Ag" and beams == 7:
        eta = ComplexPair(np.full_like(GRAZING_COS, 0.13), np.full_like(GRAZING_COS, 3.4))
        truncated = thin_film_reflectance(GRAZING_COS, 550e-9, 0.4e-6, 2.1, eta, 1.0, [1.0] * 6, NUMPY)
        assert truncated.max() > 1.05


@pytest.mark.parametrize("substrate", list(SUBSTRATES))
@pytest.mark.parametrize("beams", [3, 4, 6])
def test_every_beam_limits_are_airy_and_the_incoherent_series(substrate: str, beams: int) -> None:
    """V ≡ 1: the Airy formula for every P (no truncation error: compare test_fully_coherent_limit_is_airy's
    bound); V ≡ 0: the infinite incoherent sum |r01|² + |t01 t10 r12|²/(1 − |r10 r12|²), from the textbook
    amplitudes of ``_film_fresnel``; at 0°–89.9°, where |r10 r12| → 1."""
    eta_s = SUBSTRATES[substrate]
    for thickness_m in (0.1e-6, 1.23e-6):
        terms = _all_beam_terms(eta_s, thickness_m, 1.45, beams)
        coherent = combine_reflectance_terms(terms, [1.0] * (beams - 1))
        incoherent = combine_reflectance_terms(terms, [0.0] * (beams - 1))
        expected_coherent = _airy(GRAZING_COS, 550e-9, thickness_m, 1.0, 1.45, eta_s)
        expected_incoherent = 0.0
        for polarisation in ("s", "p"):
            r01, r12, t_product, _ = _film_fresnel(GRAZING_COS, 1.0, 1.45, eta_s, polarisation)
            series = np.abs(t_product * r12) ** 2 / (1.0 - np.abs(r01 * r12) ** 2)
            expected_incoherent = expected_incoherent + 0.5 * (np.abs(r01) ** 2 + series)
        np.testing.assert_allclose(coherent, expected_coherent, atol=1e-9)
        np.testing.assert_allclose(incoherent, expected_incoherent, atol=1e-9)
