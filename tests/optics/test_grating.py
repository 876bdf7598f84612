"""Diffraction gratings (Eqs. 19–20 read per lobe): grating equation, efficiencies, coherence, sampling."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
from scipy.signal import fftconvolve

from hgcore.optics.array_ops import NUMPY, hermite_functions
from hgcore.optics.grating import (
    CD_GRATING,
    DVD_GRATING,
    BinaryGrating,
    ModalLobe,
    gaussian_density,
    grating_eval,
    grating_pdf,
    grating_sample,
    intrinsic_variance,
    order_efficiency,
    order_efficiency_1d,
    specular_efficiency,
)
from hgcore.optics.sources import source_coefficients

ZERO_COV = (0.0, 0.0, 0.0)


def _incident(theta: float, count: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (np.full(count, math.sin(theta)), np.zeros(count), np.full(count, math.cos(theta)))


def test_efficiencies_sum_to_one() -> None:
    """Parseval: Σ_p η_p = 1. Truncating at |p| ≤ P leaves ≤ 2(1 − cos φ0)·2Σ_{p>P} 1/(π p)² ≤ 8/(π² P)."""
    orders = 4000
    for duty in (0.2, 0.5, 0.7):
        for cos_phase in (-1.0, 0.3, 0.9):
            total = sum(order_efficiency_1d(p, duty, cos_phase) for p in range(-orders, orders + 1))
            assert 1.0 - 8.0 / (math.pi**2 * orders) <= total <= 1.0 + 1e-12
    # 2-D product form: Σ_pq η_p η_q = (Σ_p η_p)².
    grating_2d = BinaryGrating(pitch_x_m=1e-6, pitch_y_m=1.3e-6, max_order=30)
    cos_phase = 0.1
    total_2d = order_efficiency(grating_2d, (0, 0), cos_phase) + sum(
        order_efficiency(grating_2d, order, cos_phase) for order in grating_2d.orders()
    )
    total_1d = sum(order_efficiency_1d(p, 0.5, cos_phase) for p in range(-30, 31))
    assert total_2d == pytest.approx(total_1d**2, rel=1e-12)


def test_cd_pit_depth_suppresses_specular_order_at_read_wavelength() -> None:
    """A pit λ/(4n) deep (φ0 = π at λ = 4 n d) gives η_0 = 1 − 4D(1−D) = 0 at D = ½."""
    eta_0 = specular_efficiency(CD_GRATING, 4 * 1.55 * 110e-9, NUMPY)
    assert eta_0 == pytest.approx(0.0, abs=1e-12)


def _peaks_along_plane(grating: BinaryGrating, theta_i: float, wavelength_m: float, step: float):
    beta = np.arange(-0.999, 0.999, step)
    wo = (beta, np.zeros_like(beta), np.sqrt(1 - beta**2))
    wi = _incident(theta_i, beta.size)
    value = grating_eval(grating, wi, wo, wavelength_m, 1.0, ZERO_COV, NUMPY)
    interior = (value[1:-1] > value[:-2]) & (value[1:-1] > value[2:]) & (value[1:-1] > 1e-3 * value.max())
    return beta[1:-1][interior]


@pytest.mark.parametrize("grating", [CD_GRATING, DVD_GRATING], ids=["CD", "DVD"])
@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 45.0])
def test_lobe_directions_obey_grating_equation(grating: BinaryGrating, theta_deg: float) -> None:
    """Local maxima of f along the plane of incidence sit at sin θ_m = m λ/Λ − sin θ_i (all m ≠ 0 with
    |sin θ_m| < 0.98 and η_m > 0), found on a grid of step h = 2e-5: |error| ≤ h. Lobes are narrow here
    (intrinsic width only, σ_β = wλ/2π ≤ 0.007), far narrower than their spacing λ/Λ ≥ 0.24."""
    step = 2e-5
    theta_i = math.radians(theta_deg)
    for wavelength_nm in range(380, 781, 50):
        wavelength_m = wavelength_nm * 1e-9
        found = _peaks_along_plane(grating, theta_i, wavelength_m, step)
        cos_phase = math.cos(4 * math.pi * grating.pit_ior * grating.depth_m / wavelength_m)
        predicted = [
            m * wavelength_m / grating.pitch_x_m - math.sin(theta_i)
            for m in range(-20, 21)
            if m != 0 and order_efficiency_1d(m, grating.duty_cycle, cos_phase) > 1e-12
        ]
        predicted = np.array([b for b in predicted if abs(b) < 0.98])
        found = found[np.abs(found) < 0.98]
        assert found.size == predicted.size  # DVD at ≥ 740 nm, normal incidence: no order propagates
        if predicted.size == 0:
            continue
        np.testing.assert_allclose(np.sort(found), np.sort(predicted), atol=step)


def _lobe_mass_and_peak(grating: BinaryGrating, source_cov, wavelength_m: float, order: int):
    """∫ f d²β over a ±8σ box around order m's centre (trapezoid: spectrally accurate for a Gaussian; the mass
    outside the box is < 1e-14)."""
    centre = order * wavelength_m / grating.pitch_x_m  # normal incidence
    sigma = math.sqrt(source_cov[0] + (grating.lobe_width_per_um * 1e6 * wavelength_m / (2 * math.pi)) ** 2)
    axis = np.linspace(-8 * sigma, 8 * sigma, 801)
    bx, by = np.meshgrid(centre + axis, axis, indexing="ij")
    wo = (bx, by, np.sqrt(1 - bx**2 - by**2))
    wi = _incident(0.0, 1)
    value = grating_eval(grating, wi, wo, wavelength_m, 0.9, source_cov, NUMPY)
    mass = float(np.trapezoid(np.trapezoid(value, axis, axis=1), axis))
    peak_wo = (np.array([centre]), np.zeros(1), np.array([math.sqrt(1 - centre**2)]))
    return mass, float(grating_eval(grating, wi, peak_wo, wavelength_m, 0.9, source_cov, NUMPY)[0])


def test_partial_coherence_dims_lobe_peaks_and_keeps_energy() -> None:
    """Fig. 1(f): C_β = Σ'/s² + (w/k)² I. Each order keeps its energy F η_m while its peak F η_m/(2π|C_β|^½)
    falls as the source's angular size grows; with Σ' = 0 the peak is the intrinsic one."""
    grating = dataclasses.replace(DVD_GRATING, lobe_width_per_um=0.05)
    wavelength_m = 500e-9
    cos_phase = math.cos(4 * math.pi * grating.pit_ior * grating.depth_m / wavelength_m)
    eta_1 = order_efficiency_1d(1, grating.duty_cycle, cos_phase)
    intrinsic_var = (0.05e6 * wavelength_m / (2 * math.pi)) ** 2
    peaks = []
    for angular_var in (0.0, 1e-5, 1e-4, 1e-3):
        mass, peak = _lobe_mass_and_peak(grating, (angular_var, 0.0, angular_var), wavelength_m, 1)
        assert mass == pytest.approx(0.9 * eta_1, rel=1e-9)
        assert peak == pytest.approx(0.9 * eta_1 / (2 * math.pi * (intrinsic_var + angular_var)), rel=1e-9)
        peaks.append(peak)
    assert all(later < earlier for earlier, later in itertools.pairwise(peaks))
    assert peaks[-1] < 0.1 * peaks[0]


def test_sampling_matches_pdf_and_weight_is_order_mass() -> None:
    """Histogram of sampled β_o vs bin integrals of the pdf (Pearson X² < K + 6√(2K), see test_rough_surface),
    and the per-sample weight f cos θ_o / pdf = F Σ η_m (propagating orders) exactly."""
    grating = BinaryGrating(pitch_x_m=1.6e-6, lobe_width_per_um=2.0)
    source_cov = (4e-3, 1e-3, 2e-3)
    rng = np.random.default_rng(17)
    count = 400_000
    wavelength_m, theta_i = 600e-9, 0.3
    wi = _incident(theta_i, count)
    wo, pdf, valid, order_weight = grating_sample(
        grating, wi, wavelength_m, source_cov, rng.random(count), rng.random(count), rng.random(count), NUMPY
    )
    value = grating_eval(grating, wi, wo, wavelength_m, 0.8, source_cov, NUMPY)
    weight = value[valid] * wo[2][valid] / pdf[valid]
    np.testing.assert_allclose(weight, 0.8 * order_weight[valid], rtol=1e-10)

    edges = np.linspace(-1.0, 1.0, 25)
    observed, _, _ = np.histogram2d(wo[0][valid], wo[1][valid], bins=(edges, edges))
    sub = 12
    fine = np.linspace(-1.0, 1.0, 24 * sub + 1)
    centres = 0.5 * (fine[1:] + fine[:-1])
    bx, by = np.meshgrid(centres, centres, indexing="ij")
    inside = bx**2 + by**2 < 1.0
    bz = np.sqrt(np.where(inside, 1.0 - bx**2 - by**2, 1.0))
    pdf_grid = grating_pdf(grating, _incident(theta_i, 1), (bx, by, bz), wavelength_m, source_cov, NUMPY)
    density = np.where(inside, pdf_grid / bz, 0.0) * (fine[1] - fine[0]) ** 2
    expected = count * density.reshape(24, sub, 24, sub).sum(axis=(1, 3))
    used = expected > 20.0
    bins = int(used.sum())
    statistic = float(np.sum((observed[used] - expected[used]) ** 2 / expected[used]))
    assert bins > 30
    assert statistic < bins + 6.0 * math.sqrt(2.0 * bins)


def test_single_mode_lobe_equals_gaussian_and_modal_mass() -> None:
    """ĉ_00 = √π gives N(0, Σ' + tI) exactly. With a second mode, ∫ density = Σ ĉ h_n(0) h_m(0) = μ(0)
    (∫ h_n = √(2π)(−1)^{n/2} h_n(0) for even n; the blur keeps mass), provided the shape stays ≥ 0 (it
    does for ĉ_20 = −0.1)."""
    source, intrinsic = (2e-3, 5e-4, 1e-3), 1e-4
    covariance = (source[0] + intrinsic, source[1], source[2] + intrinsic)
    axis = np.linspace(-0.45, 0.45, 1201)
    dx, dy = np.meshgrid(axis, axis, indexing="ij")
    single = ModalLobe(source, intrinsic, {(0, 0): math.sqrt(math.pi)}, NUMPY).density(dx, dy)
    np.testing.assert_allclose(single, gaussian_density(dx, dy, covariance, NUMPY), rtol=1e-12, atol=1e-300)
    coefficients = {(0, 0): math.sqrt(math.pi), (2, 0): -0.1}
    shape = ModalLobe(source, intrinsic, coefficients, NUMPY).density(dx, dy)
    h_at_zero = hermite_functions(np.zeros(1), 2, NUMPY)
    mu_0 = sum(value * h_at_zero[n][0] * h_at_zero[m][0] for (n, m), value in coefficients.items())
    mass = float(np.trapezoid(np.trapezoid(shape, axis, axis=1), axis))
    assert mass == pytest.approx(mu_0, rel=1e-8)


def _unclamped(lobe: ModalLobe, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """The modal lobe before its clamp at 0 (its density divided back is not enough: the clamp is lossy)."""
    y_major = (lobe.cos_phi * dx + lobe.sin_phi * dy) * lobe.inv_sqrt_q[0]
    y_minor = (lobe.cos_phi * dy - lobe.sin_phi * dx) * lobe.inv_sqrt_q[1]
    h_major = hermite_functions(y_major, lobe.degree, NUMPY)
    h_minor = hermite_functions(y_minor, lobe.degree, NUMPY)
    return sum(value * h_major[k] * h_minor[ell] for (k, ell), value in lobe.blurred.items()) * lobe.scale


def test_modal_blur_is_the_convolution_with_the_intrinsic_lobe() -> None:
    """The closed-form blur of the 16 disk modes equals a numerical convolution of the sharp modal image
    (t → 0) with N(0, tI), for a rotated anisotropic Σ' (FFT on a 481² grid; measured 4e-9 of the peak)."""
    source, intrinsic = (3e-4, 1e-4, 1.2e-4), 0.006**2
    coefficients = source_coefficients("disk", 16)
    axis = np.linspace(-0.12, 0.12, 481)
    dx, dy = np.meshgrid(axis, axis, indexing="ij")
    step = axis[1] - axis[0]
    kernel = np.exp(-(dx**2 + dy**2) / (2 * intrinsic)) / (2 * math.pi * intrinsic) * step**2
    sharp = _unclamped(ModalLobe(source, 1e-14, coefficients, NUMPY), dx, dy)
    numerical = fftconvolve(sharp, kernel, mode="same")
    closed = _unclamped(ModalLobe(source, intrinsic, coefficients, NUMPY), dx, dy)
    assert np.abs(numerical - closed).max() <= 1e-6 * closed.max()


def _blurred_disk_image(dx: np.ndarray, dy: np.ndarray, radius: float, intrinsic: float) -> np.ndarray:
    """The exact lobe of a uniform disk source of angular radius ``radius`` (rad): its image 1/(πa²) inside
    |b| < a convolved with N(0, tI), by Gauss–Legendre × midpoint quadrature over the disk."""
    nodes, weights = np.polynomial.legendre.leggauss(64)
    radii, radial_weights = 0.5 * radius * (nodes + 1.0), 0.5 * radius * weights
    angles = (np.arange(256) + 0.5) * 2.0 * math.pi / 256
    image = np.zeros_like(dx)
    for r, weight in zip(radii, radial_weights, strict=True):
        for angle in angles:
            offset_sq = (dx - r * math.cos(angle)) ** 2 + (dy - r * math.sin(angle)) ** 2
            image += weight * r * (2 * math.pi / 256) * np.exp(-offset_sq / (2 * intrinsic))
    return image / (2 * math.pi * intrinsic) / (math.pi * radius**2)


@pytest.mark.parametrize(
    ("intrinsic_std", "residual_16", "residual_1"),
    # The DVD's intrinsic lobe at 550 nm is 0.0044 (w = 0.05/µm) and Fig. 9's sphere a = 0.02 rad:
    # relative L1 residuals measured 0.064 (16 modes) and 0.281 (1 mode); a narrower lobe shows more of the
    # truncation (0.189 vs 0.443), a wider one less (0.044 vs 0.074).
    [(0.0044, 0.07, 0.28), (0.002, 0.20, 0.44), (0.01, 0.05, 0.07)],
)
def test_sixteen_modes_approach_the_exact_disk_lobe(
    intrinsic_std: float, residual_16: float, residual_1: float
) -> None:
    radius, intrinsic = 0.02, intrinsic_std**2
    source = (radius**2 / 4, 0.0, radius**2 / 4)  # a uniform disk's angular covariance
    axis = np.linspace(-3 * radius, 3 * radius, 121)
    dx, dy = np.meshgrid(axis, axis, indexing="ij")
    exact = _blurred_disk_image(dx, dy, radius, intrinsic)

    def residual(mode_count: int) -> float:
        lobe = ModalLobe(source, intrinsic, source_coefficients("disk", mode_count), NUMPY)
        return float(np.abs(lobe.density(dx, dy) - exact).sum() / exact.sum())

    assert residual(16) <= residual_16
    assert residual(1) >= residual_1
    assert residual(16) < residual(1)


def test_lobes_carry_the_order_efficiencies() -> None:
    """∫ f cos θ_o dω_o = ∫ f d²β_o = F Σ η_pq over the propagating orders: exactly for one mode (the
    Gaussian keeps the order's energy), and within the clamp's gain for 16 (a truncated expansion's negative
    tails are cut: ≤ +5 % at the DVD's lobe, measured +4.9 %)."""
    grating = dataclasses.replace(DVD_GRATING, max_order=2)
    wavelength_m, reflectance = 550e-9, 0.9
    radius = 0.02
    source = (radius**2 / 4, 0.0, radius**2 / 4)
    wi = _incident(0.0)  # orders ±1 at β = ±0.74: both lobes wholly inside the unit disk
    axis = np.linspace(-0.999, 0.999, 1601)
    bx, by = np.meshgrid(axis, axis, indexing="ij")
    inside = bx**2 + by**2 < 1.0
    wo = (bx, by, np.sqrt(np.where(inside, 1.0 - bx**2 - by**2, 1.0)))
    cos_phase = math.cos(4 * math.pi * grating.pit_ior * grating.depth_m / wavelength_m)
    expected = reflectance * sum(
        order_efficiency(grating, order, cos_phase)
        for order in grating.orders()
        if abs(-wi[0][0] + wavelength_m * order[0] / grating.pitch_x_m) < 0.9
    )
    step = axis[1] - axis[0]
    for coefficients, low, high in (
        (None, 0.999, 1.001),
        (source_coefficients("disk", 16), 1.0, 1.05),
    ):
        f = grating_eval(grating, wi, wo, wavelength_m, reflectance, source, NUMPY, coefficients)
        energy = float(np.where(inside, f, 0.0).sum() * step**2)
        assert low * expected <= energy <= high * expected, (coefficients is None, energy / expected)
    assert intrinsic_variance(grating, wavelength_m) == pytest.approx(
        (0.05e6 * wavelength_m / (2 * math.pi)) ** 2
    )


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"pitch_x_m": 0.0}, "pitch_x_m"),
        ({"pitch_x_m": 1e-6, "pitch_y_m": -1e-6}, "pitch_y_m"),
        ({"pitch_x_m": 1e-6, "duty_cycle": 1.0}, "duty_cycle"),
        ({"pitch_x_m": 1e-6, "depth_m": float("nan")}, "depth_m"),
        ({"pitch_x_m": 1e-6, "pit_ior": 0.5}, "pit_ior"),
        ({"pitch_x_m": 1e-6, "lobe_width_per_um": 0.0}, "lobe_width_per_um"),
        ({"pitch_x_m": 1e-6, "max_order": 0}, "max_order"),
    ],
)
def test_invalid_grating_names_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        BinaryGrating(**kwargs)
