"""Coherence diagnostics (BRIEF), §4.1 positive-definite repair, μ(ξ) vs van Cittert–Zernike."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import j1

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.coherence import (
    coherence_diagnostics,
    degree_of_coherence,
    diagnostics_components,
    make_positive_definite,
    shape_matrix_from_covariance,
    shape_matrix_from_log_hessian,
)
from hgcore.optics.expansion import reconstruct
from hgcore.optics.sources import source_coefficients

WAVELENGTH_M = 550e-9
K = 2 * math.pi / WAVELENGTH_M
FIRST_ZERO_OF_J1 = 3.8317059702075125
# Max |μ_N − 2J₁(v)/v| over the central lobe, recorded by test_disk_error_decreases_with_modes.
DISK_ERRORS: dict[int, float] = {}


def rotated(variances: tuple[float, float], angle: float) -> np.ndarray:
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return rotation @ np.diag(variances) @ rotation.T


def test_make_positive_definite_flips_and_clips() -> None:
    # Eigenvalues (3, −2, 1e-20) with a known rotation → (3, 2, ε); eigenvectors are kept.
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    matrix = q @ np.diag([3.0, -2.0, 1e-20]) @ q.T
    repaired = make_positive_definite(matrix, 1e-6)
    np.testing.assert_allclose(repaired, q @ np.diag([3.0, 2.0, 1e-6]) @ q.T, atol=1e-12)
    np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(repaired)), [1e-6, 2.0, 3.0], atol=1e-12)
    already = rotated((2.0, 0.5), 0.3)
    np.testing.assert_allclose(make_positive_definite(already, 1e-9), already, atol=1e-15)
    with pytest.raises(ValueError, match=r"^epsilon:"):
        make_positive_definite(already, 0.0)
    with pytest.raises(ValueError, match=r"^matrix:"):
        make_positive_definite([[1.0, float("nan")], [0.0, 1.0]], 1e-9)


def test_lemma_4_4_sign_gives_theta_equal_inverse_covariance() -> None:
    # ln f̃ of a Gaussian intensity with covariance Σ is −½ζᵀΣζ: ∂² ln f̃ = −Σ and Θ = −(−Σ)⁻¹ = Σ⁻¹.
    sigma = rotated((4e-6, 1e-6), 0.7)
    np.testing.assert_allclose(shape_matrix_from_log_hessian(-sigma), np.linalg.inv(sigma), rtol=1e-12)
    # A Hessian with a wrong-sign eigenvalue (numerical noise) is repaired to positive-definite (§4.1).
    noisy = -np.diag([4e-6, -1e-6])
    np.testing.assert_allclose(shape_matrix_from_log_hessian(noisy), np.diag([2.5e5, 1e6]), rtol=1e-12)
    with pytest.raises(ValueError, match=r"^hessian:"):
        shape_matrix_from_log_hessian(np.zeros((2, 2)))


def test_diagnostics_eigen_decomposition_angle_and_area() -> None:
    # Σ with variances (s_a², s_b²) along axes at angle φ: M = (k/r)²Σ, ℓ = r/(k s) (1/√e half-widths);
    # the longer ℓ₁ belongs to the smaller variance, i.e. lies along φ + π/2.
    s_a, s_b, phi, r = 2e-3, 5e-4, 0.4, 1.7
    diagnostics = coherence_diagnostics(rotated((s_a**2, s_b**2), phi), r, WAVELENGTH_M)
    assert diagnostics.l1_um == pytest.approx(1e6 * r / (K * s_b), rel=1e-12)
    assert diagnostics.l2_um == pytest.approx(1e6 * r / (K * s_a), rel=1e-12)
    assert diagnostics.anisotropy == pytest.approx(s_a / s_b, rel=1e-12)
    assert diagnostics.area_um2 == pytest.approx(math.pi * diagnostics.l1_um * diagnostics.l2_um, rel=1e-15)
    assert diagnostics.angle == pytest.approx(phi + math.pi / 2 - math.pi, abs=1e-12)  # wrapped
    np.testing.assert_allclose(
        diagnostics.M_per_m2, (K / r) ** 2 * rotated((s_a**2, s_b**2), phi), rtol=1e-12
    )
    # μ₀ = exp(−½ξᵀMξ) drops to e^{−½} at ξ = ℓ₁ along the ℓ₁ axis.
    axis = np.array([math.cos(diagnostics.angle), math.sin(diagnostics.angle)]) * diagnostics.l1_um * 1e-6
    assert float(axis @ diagnostics.M_per_m2 @ axis) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize(
    ("sigma", "expected_angle"),
    [
        (np.diag([1e-6, 1e-6]), 0.0),  # isotropic: angle 0 by convention
        (np.diag([1e-6, 4e-6]), 0.0),  # narrow along x ⇒ ℓ₁ along x
        (np.diag([4e-6, 1e-6]), math.pi / 2),  # narrow along y ⇒ ℓ₁ along y: +π/2, never −π/2
        (rotated((4e-6, 1e-6), math.pi / 4), -math.pi / 4),  # φ + π/2 = 3π/4 wraps to −π/4
        (rotated((4e-6, 1e-6), -math.pi / 3), -math.pi / 3 + math.pi / 2),
    ],
)
def test_angle_conventions(sigma: np.ndarray, expected_angle: float) -> None:
    angle = coherence_diagnostics(sigma, 1.0).angle
    assert -math.pi / 2 < angle <= math.pi / 2
    assert angle == pytest.approx(expected_angle, abs=1e-12)


def test_diagnostics_validate_inputs() -> None:
    with pytest.raises(ValueError, match=r"^sigma_m2:"):
        coherence_diagnostics(np.diag([1e-6, -1e-6]), 1.0)
    with pytest.raises(ValueError, match=r"^sigma_m2:"):
        coherence_diagnostics([[1e-6, 2e-7], [0.0, 1e-6]], 1.0)
    with pytest.raises(ValueError, match=r"^r_m:"):
        coherence_diagnostics(np.eye(2), 0.0)
    with pytest.raises(ValueError, match=r"^sigma_m2:"):
        shape_matrix_from_covariance(np.zeros((2, 2)))


def test_van_cittert_zernike_gaussian_source_exact() -> None:
    # A Gaussian source of std σ gives μ(ξ) = exp(−½(kσ|ξ|/r)²) exactly (VCZ: μ = F{I}(kξ/r)/F{I}(0)).
    # Its expansion has ĉ₀₀ = √π and nothing else, so 1 and 16 modes both agree to rounding (1e-12).
    sigma_m, r = 3e-4, 2.0
    xi = np.linspace(0.0, 5.0 * r / (K * sigma_m), 50)
    exact = np.exp(-0.5 * (K * sigma_m * xi / r) ** 2)
    for modes in (1, 16):
        coefficients = source_coefficients("gaussian", modes)
        mu = degree_of_coherence(
            (xi * 0.6, xi * 0.8), (sigma_m**2, 0.0, sigma_m**2), r, WAVELENGTH_M, coefficients
        )
        np.testing.assert_allclose(mu, exact, rtol=0.0, atol=1e-12)


def test_uniform_disk_curvature_matched_by_zeroth_mode() -> None:
    # 2J₁(v)/v = 1 − v²/8 + v⁴/192 − …, v = kRξ/r; the 0th mode exp(−½(k/r)²(R²/4)ξ²) = 1 − v²/8 + v⁴/128 …
    # so (1 − μ)/v² → 1/8 for both, with O(v²) differences: at v = 1e-2 both are within v²/64 of 1/8, and
    # float64 rounding of 1 − μ ≈ 1.25e-5 contributes < 1e-10 relative.
    radius, r, v = 1e-3, 0.5, 1e-2
    xi = v * r / (K * radius)
    mu0 = degree_of_coherence(
        (xi, 0.0), (radius**2 / 4, 0.0, radius**2 / 4), r, WAVELENGTH_M, source_coefficients("sphere", 1)
    )
    airy = 2 * j1(v) / v
    assert abs((1 - mu0) / v**2 - 1 / 8) < v**2 / 64
    assert abs((1 - airy) / v**2 - 1 / 8) < v**2 / 64
    assert abs((1 - mu0) - (1 - airy)) < v**4 / 64


def central_lobe_error(modes: int) -> float:
    """max |μ_N(v) − 2J₁(v)/v| over v ∈ [0, j₁,₁] and three directions (the expansion is radial)."""
    radius, r = 1e-3, 1.0
    v = np.linspace(1e-9, FIRST_ZERO_OF_J1, 500)
    xi = v * r / (K * radius)
    coefficients = source_coefficients("disk", modes)
    errors = []
    for phi in (0.0, 0.5, 1.2):
        mu = degree_of_coherence(
            (xi * math.cos(phi), xi * math.sin(phi)),
            (radius**2 / 4, 0.0, radius**2 / 4),
            r,
            WAVELENGTH_M,
            coefficients,
        )
        errors.append(np.max(np.abs(mu - 2 * j1(v) / v)))
    return float(max(errors))


def test_disk_error_decreases_with_modes() -> None:
    # v ∈ [0, j₁,₁ ≈ 3.83]: the central lobe of 2J₁(v)/v, which holds the coherence area; outside it
    # |μ| < 0.132. Modes 1, 4, 16 close orders 0, 2, 6, so each truncation is rotation-invariant and the
    # constrained-L² expansion (μ(0) = 1) is radial. Measured: 0.160, 0.111, 0.033 (closing note).
    for modes in (1, 4, 16):
        DISK_ERRORS[modes] = central_lobe_error(modes)
    print("uniform disk, max |μ_N − 2J1(v)/v| on v∈[0,3.83]:", DISK_ERRORS)
    assert DISK_ERRORS[1] > DISK_ERRORS[4] > DISK_ERRORS[16]
    # The 0th mode's error is the Gaussian's value at the first zero: exp(−j₁,₁²/8) ≈ 0.160.
    assert DISK_ERRORS[1] == pytest.approx(math.exp(-(FIRST_ZERO_OF_J1**2) / 8), abs=1e-6)
    assert DISK_ERRORS[16] < 0.05


def test_whitened_series_equals_eq5_series_with_rescaled_coefficients() -> None:
    # Independent paths: Σĉ h_n(u₁)h_m(u₂) (whitened) must equal Σ c_nm Ψ^Θ_nm(k/r·ξ) (Eq. 5 recurrence) with
    # c_nm = ĉ_nm |Θ|^{1/4} θ₁^{n/2} θ₂^{m/2} in Σ's principal frame (Θ = diag(θ₁, θ₂) = Σ⁻¹). Rounding only.
    sigma_major, sigma_minor, r = 4e-6, 1e-6, 0.8
    coefficients = source_coefficients("rect", 16)
    xi = np.linspace(-2.0, 2.0, 9) * r / (K * 1e-3)
    eta = np.linspace(1.5, -1.0, 9) * r / (K * 1e-3)
    mu = degree_of_coherence((xi, eta), (sigma_major, 0.0, sigma_minor), r, WAVELENGTH_M, coefficients)
    theta = np.diag([1 / sigma_major, 1 / sigma_minor])
    scaled = {
        (n, m): c * np.linalg.det(theta) ** 0.25 * theta[0, 0] ** (n / 2) * theta[1, 1] ** (m / 2)
        for (n, m), c in coefficients.items()
    }
    eq5 = reconstruct(scaled, theta, [K / r * xi, K / r * eta])
    np.testing.assert_allclose(mu, eq5, rtol=0.0, atol=1e-10)


def test_drjit_degree_of_coherence_and_diagnostics_equal_numpy() -> None:
    # Single-precision Dr.Jit evaluation of the same code: Hermite recurrences to degree 6 plus a 2×2
    # eigen-decomposition, ~50 float32 operations (ε ≈ 6e-8) with |ĉ| ≲ 2 ⇒ agreement to 1e-4 absolute on
    # μ ∈ [−1, 1]; diagnostics to 1e-5 relative.
    from worker.mitsuba_setup import configured_mitsuba

    mi = configured_mitsuba()
    import drjit as dr

    from worker.render.drjit_ops import drjit_ops

    rng = np.random.default_rng(2)
    sigma = rotated((3e-6, 7e-7), 0.9)
    r = 1.3
    xi = rng.uniform(-3.0, 3.0, size=(2, 128)) * r / (K * 1e-3)
    coefficients = source_coefficients("disk", 16)
    entries = (sigma[0, 0], sigma[0, 1], sigma[1, 1])
    reference = degree_of_coherence((xi[0], xi[1]), entries, r, WAVELENGTH_M, coefficients, NUMPY)
    jit = degree_of_coherence(
        (mi.Float(xi[0]), mi.Float(xi[1])),
        tuple(mi.Float(np.full(128, e)) for e in entries),
        mi.Float(r),
        WAVELENGTH_M,
        coefficients,
        drjit_ops(),
    )
    np.testing.assert_allclose(np.array(dr.ravel(jit)), reference, rtol=0.0, atol=1e-4)
    jit_diag = diagnostics_components(*(mi.Float(e) for e in entries), mi.Float(r), WAVELENGTH_M, drjit_ops())
    reference_diag = coherence_diagnostics(sigma, r)
    for name in ("l1_um", "l2_um", "angle", "anisotropy", "area_um2"):
        assert float(dr.ravel(getattr(jit_diag, name))[0]) == pytest.approx(
            getattr(reference_diag, name), rel=1e-5
        )


@pytest.mark.parametrize("source", ["disk", "rect"])
def test_degenerate_covariance_is_fully_coherent_along_its_null_axis_not_nan(source: str) -> None:
    """Σ⊥ = 0 (a point source) gives μ = 1 everywhere; a rank-one Σ⊥ (a line source seen end-on, det rounded
    below 0) gives μ along its null axis = μ(0) = 1: the HG sum at u = 0, which the normalisation fixes."""
    coefficients = source_coefficients(source, 16)
    xi = (np.array([0.0, 3e-6, 0.0]), np.array([0.0, 0.0, 3e-6]))
    zero = np.zeros(3)
    with np.errstate(invalid="ignore"):  # λ₂ = 0/0 inside principal_axes_components, then replaced
        mu_point = degree_of_coherence(xi, (zero, zero, zero), 1.0, WAVELENGTH_M, coefficients)
    np.testing.assert_allclose(mu_point, 1.0, atol=1e-12)
    rank_one = (np.full(3, 1e-6), zero, np.full(3, -1e-22))  # Σ_yy a rounding error below 0
    mu = degree_of_coherence(xi, rank_one, 1.0, WAVELENGTH_M, coefficients)
    assert np.all(np.isfinite(mu))
    assert mu[2] == pytest.approx(1.0, abs=1e-12)  # separation along the null (y) axis
