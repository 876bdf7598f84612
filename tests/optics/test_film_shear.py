"""The thin-film shear (``thin_film.film_shear``) against a two-beam partially coherent computation from rays.

Independent reference: partially coherent light as an incoherent ensemble of plane waves whose transverse
direction cosines β (in the plane ⟂ the mean direction k̂₀) are Gaussian with covariance C — the field a
distant, spatially incoherent source produces; its mutual coherence at a transverse separation ξ is
μ(ξ) = exp(−½ (k n₀)² ξᵀCξ), k = 2π/λ. For every plane wave the two reflected beams are traced explicitly
(Snell's law in vector form, the path to the bottom interface and back, the exit point): beam 1 leaves the
top at Q having entered at P, beam 0 is reflected at Q, and their phase difference is
δ = k (n_f L_film − n₀ k̂·(Q − P)). Both reflected waves are plane waves along the same direction, so at any
observer the ensemble-averaged two-beam intensity is |a₀|² + |a₁|² + 2|a₀a₁| Re⟨e^{iδ}⟩: its fringe
visibility is V = |⟨e^{i(δ−δ₀)}⟩| (Gauss–Hermite quadrature over β, 48² nodes: exact to < 1e-9 here).

The renderer's model: V = μ at the transverse projection of the shear s. To first order in β the two agree
exactly when s is the physical shear, because ∂δ/∂θ₀ = −k n₀ · 2τ tan θ_t cos θ₀ (the phase gradient over
the ensemble is the transverse shear). The remaining difference is the curvature of δ(β): with the
quadratic term b = ∂²δ/∂θ₀² (finite differences of the ray δ) the Gaussian average changes |V| by at most
≈ |b| σ²(1 + a²σ²), a = ∂δ/∂θ₀, σ² the in-plane variance — the tolerance used. Eq. (18)'s reading
τ sin θ₀ (the transverse part of τn̂) is tested to be rejected at oblique incidence with the same tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.thin_film import film_shear

WAVELENGTH_M = 550e-9
WAVENUMBER_PER_M = 2.0 * math.pi / WAVELENGTH_M


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame(normal: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Transverse axes of ``direction``: e₁ in the plane of incidence, e₂ ⟂ to it (any pair at normal
    incidence, where that plane is undefined)."""
    cross = np.cross(direction, normal)
    if np.linalg.norm(cross) < 1e-12:
        cross = np.cross(direction, [1.0, 0.0, 0.0])
    e2 = _unit(cross)
    return np.cross(e2, direction), e2


def ray_phase(k_hat: np.ndarray, normal: np.ndarray, thickness_m: float, n_film: float, n_out: float):
    """δ of beam 1 relative to beam 0 for plane waves ``k_hat`` (…, 3), traced through the film."""
    up = np.where((k_hat @ normal < 0.0)[..., None], normal, -normal)  # the normal on the incident side
    cos_i = -np.sum(k_hat * up, axis=-1)
    ratio = n_out / n_film
    cos_t = np.sqrt(1.0 - ratio**2 * (1.0 - cos_i**2))
    k_film = ratio * k_hat + (ratio * cos_i - cos_t)[..., None] * up  # Snell, vector form
    leg = thickness_m / cos_t  # P → bottom, and bottom → Q after the mirror reflection
    tangential_step = leg[..., None] * (k_film + cos_t[..., None] * up)
    exit_minus_entry = 2.0 * tangential_step
    path_difference = n_film * 2.0 * leg - n_out * np.sum(k_hat * exit_minus_entry, axis=-1)
    return WAVENUMBER_PER_M * path_difference


def ray_visibility(
    k_mean: np.ndarray,
    normal: np.ndarray,
    covariance: np.ndarray,
    thickness_m: float,
    n_film: float,
    n_out: float,
) -> float:
    """|⟨e^{i(δ − δ₀)}⟩| over plane waves with Gaussian transverse direction cosines (covariance: e₁, e₂)."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(48)
    weights = weights / weights.sum()
    chol = np.linalg.cholesky(covariance)
    z1, z2 = np.meshgrid(nodes, nodes, indexing="ij")
    w = np.outer(weights, weights)
    beta = np.stack([z1, z2], axis=-1) @ chol.T
    e1, e2 = _frame(normal, k_mean)
    k_hat = _unit(k_mean + beta[..., :1] * e1 + beta[..., 1:] * e2)
    delta = ray_phase(k_hat, normal, thickness_m, n_film, n_out)
    delta0 = ray_phase(k_mean[None], normal, thickness_m, n_film, n_out)[0]
    return float(abs(np.sum(w * np.exp(1j * (delta - delta0)))))


def model_visibility(separation: np.ndarray, k_mean, normal, covariance, n_out: float) -> float:
    e1, e2 = _frame(normal, k_mean)
    xi = np.array([separation @ e1, separation @ e2])
    return math.exp(-0.5 * (WAVENUMBER_PER_M * n_out) ** 2 * xi @ covariance @ xi)


def curvature_tolerance(k_mean, normal, covariance, thickness_m, n_film, n_out) -> float:
    """≈ |b|σ²(1 + a²σ²) (+ quadrature 1e-9): what δ's departure from linear in β does to V."""
    e1, _ = _frame(normal, k_mean)
    h = 1e-4
    phases = [
        ray_phase(_unit(k_mean + t * h * e1)[None], normal, thickness_m, n_film, n_out)[0] for t in (-1, 0, 1)
    ]
    slope = (phases[2] - phases[0]) / (2 * h)
    curvature = (phases[2] - 2 * phases[1] + phases[0]) / h**2
    variance = covariance[0, 0]
    return abs(curvature) * variance * (1.0 + slope**2 * variance) + 1e-9


NORMAL = _unit(np.array([0.3, -0.2, 0.93]))  # a tilted film: the shear is a world-space vector


def incident(theta_deg: float, azimuth_deg: float = 40.0) -> np.ndarray:
    """Unit propagation direction arriving at polar angle θ on NORMAL's side (k̂·n̂ < 0)."""
    helper = np.array([1.0, 0.0, 0.0])
    t1 = _unit(helper - (helper @ NORMAL) * NORMAL)
    t2 = np.cross(NORMAL, t1)
    theta, phi = math.radians(theta_deg), math.radians(azimuth_deg)
    tangent = math.cos(phi) * t1 + math.sin(phi) * t2
    return -math.cos(theta) * NORMAL + math.sin(theta) * tangent


def _shear(k_mean: np.ndarray, thickness_m: float, n_film: float, n_out: float) -> np.ndarray:
    return np.array(film_shear(tuple(NORMAL), tuple(k_mean), thickness_m, n_film, n_out, NUMPY), dtype=float)


@pytest.mark.parametrize("theta_deg", [0.0, 15.0, 35.0, 60.0, 80.0])
@pytest.mark.parametrize(("n_film", "n_out"), [(1.38, 1.0), (2.1, 1.0), (1.6, 1.33)])
def test_shear_gives_the_ray_traced_two_beam_visibility(
    theta_deg: float, n_film: float, n_out: float
) -> None:
    """Isotropic and strongly anisotropic angular spreads; τ chosen so that V ≈ 0.5 in-plane at 35°."""
    k_mean = incident(theta_deg)
    sigma = 1.5e-3  # rad: a source 0.17° across
    thickness_m = 60e-6
    for covariance in (np.diag([sigma**2, sigma**2]), np.diag([sigma**2, (4 * sigma) ** 2])):
        reference = ray_visibility(k_mean, NORMAL, covariance, thickness_m, n_film, n_out)
        shear = _shear(k_mean, thickness_m, n_film, n_out)
        model = model_visibility(shear, k_mean, NORMAL, covariance, n_out)
        tolerance = curvature_tolerance(k_mean, NORMAL, covariance, thickness_m, n_film, n_out)
        assert abs(model - reference) <= tolerance, (theta_deg, covariance[1, 1], model, reference, tolerance)


@pytest.mark.parametrize("theta_deg", [35.0, 60.0])
def test_born_reading_tau_sin_theta_disagrees_with_the_rays(theta_deg: float) -> None:
    """The transverse part of τn̂ (length τ sin θ₀) gives a visibility the ray computation rules out."""
    k_mean, n_film, n_out, thickness_m = incident(theta_deg), 1.38, 1.0, 60e-6
    covariance = np.diag([1.5e-3**2, 1.5e-3**2])
    reference = ray_visibility(k_mean, NORMAL, covariance, thickness_m, n_film, n_out)
    tolerance = curvature_tolerance(k_mean, NORMAL, covariance, thickness_m, n_film, n_out)
    born = model_visibility(thickness_m * NORMAL, k_mean, NORMAL, covariance, n_out)
    assert abs(born - reference) > 20 * tolerance, (born, reference, tolerance)


def test_shear_geometry() -> None:
    """|s| = 2τ tan θ_t along the incident light's tangential direction; s·n̂ = 0; 0 at normal incidence and
    beyond the film's critical angle; multiples of the round trip scale it linearly (beam d: d·s)."""
    thickness_m, n_film = 0.4e-6, 1.5
    for theta_deg in (0.0, 20.0, 50.0, 85.0):
        k_mean = incident(theta_deg)
        shear = _shear(k_mean, thickness_m, n_film, 1.0)
        sin_t = math.sin(math.radians(theta_deg)) / n_film
        assert np.linalg.norm(shear) == pytest.approx(
            2 * thickness_m * sin_t / math.sqrt(1 - sin_t**2), rel=1e-12
        )
        assert abs(shear @ NORMAL) < 1e-18
        tangential = k_mean - (k_mean @ NORMAL) * NORMAL
        assert shear @ tangential >= 0.0
    # a film rarer than the exterior: beyond n_f/n_0 = sin θ₀ nothing propagates in it
    assert np.all(_shear(incident(70.0), thickness_m, 1.2, 1.33) == 0.0)
    # either side's normal gives the same shear
    flipped = film_shear(tuple(-NORMAL), tuple(incident(30.0)), thickness_m, n_film, 1.0, NUMPY)
    assert np.allclose(flipped, _shear(incident(30.0), thickness_m, n_film, 1.0), rtol=1e-12, atol=0)
