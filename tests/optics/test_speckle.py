"""Partially-coherent speckle (Eqs. 21–22) for small particle sets against closed-form limits."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from hgcore.optics.hg import dual_hg_functions
from hgcore.optics.speckle import angular_coherence_coefficients, pair_coherence, speckle_intensity

FRAME = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # incident beam along z
ZEROTH_MODE = {(0, 0): math.sqrt(math.pi)}
WAVELENGTH_M = 550e-9
DISTANCE_M = 1.0


def _particles(rng: np.random.Generator, count: int, side_m: float) -> tuple[np.ndarray, np.ndarray]:
    return rng.uniform(0.0, side_m, size=(count, 3)), rng.uniform(0.2, 1.0, size=count)


def test_full_coherence_is_fully_developed_speckle() -> None:
    """Σ' = 0 ⇒ μ ≡ 1 ⇒ I(φ) = |Σ_j a_j e^{−i p_j·φ}|² (exact identity; float64 round-off over N² terms)."""
    rng = np.random.default_rng(1)
    positions, amplitudes = _particles(rng, 25, 20e-6)
    phi = rng.normal(scale=2e6, size=(40, 3))
    intensity = speckle_intensity(
        positions, amplitudes, phi, FRAME, (0.0, 0.0, 0.0), DISTANCE_M, WAVELENGTH_M, ZEROTH_MODE
    )
    field = np.exp(-1j * phi @ positions.T) @ amplitudes
    np.testing.assert_allclose(intensity, np.abs(field) ** 2, rtol=1e-10, atol=1e-12)


def test_incoherent_limit_is_intensity_sum() -> None:
    """A huge source (σ' = 1 m at 1 m) makes μ_jl ≤ exp(−½ (kσ' d_min)²) negligible for j ≠ l, so
    |I − Σ a_j²| ≤ Σ_{j≠l} a_j a_l μ_jl, which we bound by the computed μ."""
    rng = np.random.default_rng(2)
    positions, amplitudes = _particles(rng, 20, 50e-6)
    sigma = (1.0, 0.0, 1.0)
    phi = rng.normal(scale=5e6, size=(30, 3))
    intensity = speckle_intensity(
        positions, amplitudes, phi, FRAME, sigma, DISTANCE_M, WAVELENGTH_M, ZEROTH_MODE
    )
    coherence = pair_coherence(positions, FRAME, sigma, DISTANCE_M, WAVELENGTH_M, ZEROTH_MODE)
    off_diagonal = np.outer(amplitudes, amplitudes) * np.abs(coherence - np.diag(np.diag(coherence)))
    np.testing.assert_allclose(np.diag(coherence), 1.0, rtol=1e-12)
    assert np.all(np.abs(intensity - np.sum(amplitudes**2)) <= off_diagonal.sum() + 1e-12)


def test_mean_over_particle_sets_is_incoherent_sum() -> None:
    """Positions uniform in a cube of side L: E[cos((p_l − p_j)·φ)] = Π_i sinc²(φ_i L/2) = 0 when φ_x L/2 = π,
    so E[I(φ)] = Σ a_j² for any coherence. Monte Carlo over K sets: |mean − Σ a²| < 5 standard errors."""
    rng = np.random.default_rng(3)
    side_m = 10e-6
    amplitudes = np.linspace(0.3, 1.0, 12)
    phi = np.array([[2 * math.pi / side_m, 0.0, 0.0]])
    sigma = (1e-6, 0.0, 1e-6)  # partially coherent: μ over 10 µm ≈ exp(−½(k·1e-3·d)²) ∈ (0.95, 1]
    samples = []
    for _ in range(3000):
        positions = rng.uniform(0.0, side_m, size=(amplitudes.size, 3))
        samples.append(
            speckle_intensity(
                positions, amplitudes, phi, FRAME, sigma, DISTANCE_M, WAVELENGTH_M, ZEROTH_MODE
            )[0]
        )
    samples = np.array(samples)
    standard_error = samples.std(ddof=1) / math.sqrt(samples.size)
    assert abs(samples.mean() - np.sum(amplitudes**2)) < 5.0 * standard_error


def test_partial_coherence_lowers_speckle_contrast() -> None:
    """Speckle contrast std(I)/mean(I) over directions: ≈ 1 for coherent light (fully developed speckle with
    many particles), falling towards 0 as the source grows."""
    rng = np.random.default_rng(4)
    positions, amplitudes = _particles(rng, 60, 30e-6)
    amplitudes = np.ones_like(amplitudes)
    phi = rng.normal(scale=3e6, size=(1500, 3))
    contrasts = []
    for sigma_m in (0.0, 3e-3, 1e-2, 1e-1):
        sigma = (sigma_m**2, 0.0, sigma_m**2)
        intensity = speckle_intensity(
            positions, amplitudes, phi, FRAME, sigma, DISTANCE_M, WAVELENGTH_M, ZEROTH_MODE
        )
        contrasts.append(intensity.std() / intensity.mean())
    assert 0.8 < contrasts[0] < 1.2
    assert all(later < earlier for earlier, later in itertools.pairwise(contrasts))
    assert contrasts[-1] < 0.3


def test_angular_coherence_coefficients_match_quadrature() -> None:
    """Eq. (21) single-sum form vs ∫ f̃_σ(ζ) Ψ̃^Θ_nm(ζ) d²ζ by Gauss–Hermite quadrature after ζ = √2 Θ^{½} u
    (integrand poly(u)·e^{−iζ·p}·e^{−|u|²} with |ζ·p| ≲ 6: 80-point rule, remainder < 1e-30; tolerance 1e-9
    relative from float64 summation of 6400 terms)."""
    rng = np.random.default_rng(5)
    positions = np.column_stack(
        [rng.normal(scale=0.6e-6, size=4), rng.normal(scale=0.6e-6, size=4), np.zeros(4)]
    )
    amplitudes = np.array([1.0, 0.5, 0.8, 0.3])
    rotation = np.array([[math.cos(0.4), -math.sin(0.4)], [math.sin(0.4), math.cos(0.4)]])
    theta = rotation @ np.diag([2.0e12, 0.7e12]) @ rotation.T  # 1/m²
    coefficients = angular_coherence_coefficients(positions, amplitudes, FRAME, theta, 4)
    nodes, weights = np.polynomial.hermite.hermgauss(80)
    uu = np.array(np.meshgrid(nodes, nodes, indexing="ij")).reshape(2, -1)
    ww = np.outer(weights, weights).ravel()
    eigenvalues, eigenvectors = np.linalg.eigh(theta)
    transform = math.sqrt(2.0) * (eigenvectors * np.sqrt(eigenvalues)) @ eigenvectors.T
    zeta = transform @ uu
    jacobian = abs(np.linalg.det(transform))
    dual = dual_hg_functions(list(zeta), theta.tolist(), 4)
    f_tilde = (amplitudes**2) @ np.exp(-1j * positions[:, :2] @ zeta)
    for alpha, expected in coefficients.items():
        numeric = np.sum(ww * np.exp(np.sum(uu * uu, axis=0)) * f_tilde * dual[alpha]) * jacobian
        assert abs(numeric - expected) <= 1e-9 * max(1.0, abs(expected)), (alpha, numeric, expected)
    assert abs(coefficients[(1, 0)].real) < 1e-12 * abs(coefficients[(0, 0)])  # odd orders are imaginary


@pytest.mark.parametrize(
    ("positions", "amplitudes", "field"),
    [
        (np.zeros((3, 2)), np.ones(3), "positions_m"),
        (np.zeros((3, 3)), np.ones(2), "amplitudes"),
        (np.zeros((3, 3)), -np.ones(3), "amplitudes"),
    ],
)
def test_invalid_particles_name_parameter(positions: np.ndarray, amplitudes: np.ndarray, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        speckle_intensity(
            positions, amplitudes, np.ones((1, 3)), FRAME, (0.0, 0.0, 0.0), 1.0, 5e-7, ZEROTH_MODE
        )
