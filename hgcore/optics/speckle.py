"""Partially-coherent speckle from a small set of point scatterers: Eqs. (21)–(22) (NumPy reference).

A volume holds N point particles at p_j (m) with real, non-negative scattering coefficients a_j, so
σ(r) = Σ_j a_j δ³(r − p_j). Light arrives from a source at distance s (m) with transverse covariance Σ'
(m², in the incident beam's transverse frame (e_1, e_2)) and whitened HG coefficients ĉ (those of
``hgcore.optics.sources.source_coefficients``; ĉ_00 = √π is the 0th mode).

Eq. (22), the interference term of Theorem 5.1(i): the speckle intensity at the scattering vector
φ = k(r̂ + ŝ) (rad/m) is

    I(φ) = Σ_{j,l} μ(p_l − p_j) a_j a_l e^{−i(p_l − p_j)·φ} = Σ_{j,l} μ(p_l − p_j) a_j a_l cos((p_l − p_j)·φ),

where μ(d) is the incident degree of coherence at the transverse part of the separation d (the incident HG
expansion evaluated at kQ'd/s; ``hgcore.optics.coherence.degree_of_coherence``); μ is even, so I is real.
Full coherence (μ ≡ 1) gives the fully developed speckle |Σ_j a_j e^{−ip_j·φ}|²; incoherent light (μ = δ)
gives Σ_j a_j²; averaging over particle positions gives the incoherent sum where the positions' characteristic
function vanishes.

Eq. (21), the HG coefficients of the angular coherence f̃_σ = F{⟨|σ|²⟩}: for point particles
⟨|σ|²⟩ = Σ_j a_j² δ(r − p_j), so f̃_σ(ζ) = Σ_j a_j² e^{−iζ·p_j} and, by the Fourier pair of Eq. (9) applied to
the dual function (F{Ψ̃^Θ_nm}(x) = 2π(−i)^{n+m} Ψ^{Θ⁻¹}_nm(x) in two dimensions),

    ⟨f̃_σ | Ψ̃^Θ_nm(Qζ)⟩ = 2π (−i)^{n+m} Σ_j a_j² Ψ^{Θ⁻¹}_nm(Q p_j),

with Q p_j the particle positions projected on the transverse frame (m), ζ in rad/m and Θ in 1/m².
The paper prints this sum as a double sum Σ_{jl} e^{−i s_l·p_j} a_j a_l Ψ̃(Qp_l); the single sum above is what
Eqs. (8), (9) and (13) give for point particles, and it is what we implement (docs/physics_interactions.md).
Odd orders n + m come out imaginary, as §4 predicts for a non-centro-symmetric f̃; they are returned as
complex numbers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.coherence import degree_of_coherence
from hgcore.optics.hg import hg_functions


def _validated_particles(positions_m: np.ndarray, amplitudes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    positions = np.asarray(positions_m, dtype=float)
    weights = np.asarray(amplitudes, dtype=float)
    if positions.ndim != 2 or positions.shape[1] != 3 or positions.shape[0] < 1:
        raise InputError(f"positions_m: must have shape (N, 3) with N ≥ 1, got {positions.shape}")
    if weights.shape != (positions.shape[0],):
        raise InputError(f"amplitudes: must have shape ({positions.shape[0]},), got {weights.shape}")
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(weights))):
        raise InputError("positions_m: positions and amplitudes must be finite")
    if np.any(weights < 0.0):
        raise InputError("amplitudes: scattering coefficients must be non-negative")
    return positions, weights


def pair_coherence(
    positions_m: np.ndarray,
    frame: tuple[Sequence[float], Sequence[float]],
    sigma_m2: tuple[float, float, float],
    distance_m: float,
    wavelength_m: float,
    coefficients: Mapping[tuple[int, int], float],
) -> np.ndarray:
    """μ_jl = μ(p_l − p_j) (N×N) of the incident light over every particle pair (transverse separations)."""
    if not (math.isfinite(distance_m) and distance_m > 0.0):
        raise InputError(f"distance_m: must be finite and > 0, got {distance_m}")
    if not (math.isfinite(wavelength_m) and wavelength_m > 0.0):
        raise InputError(f"wavelength_m: must be finite and > 0, got {wavelength_m}")
    axis_1, axis_2 = (np.asarray(axis, dtype=float) for axis in frame)
    separations = positions_m[None, :, :] - positions_m[:, None, :]  # [j, l] = p_l − p_j
    xi = (separations @ axis_1, separations @ axis_2)
    return degree_of_coherence(xi, sigma_m2, distance_m, wavelength_m, coefficients, NUMPY)


def speckle_intensity(
    positions_m: np.ndarray,
    amplitudes: np.ndarray,
    scattering_vectors_per_m: np.ndarray,
    frame: tuple[Sequence[float], Sequence[float]],
    sigma_m2: tuple[float, float, float],
    distance_m: float,
    wavelength_m: float,
    coefficients: Mapping[tuple[int, int], float],
) -> np.ndarray:
    """Eq. (22): I(φ) for each row φ of ``scattering_vectors_per_m`` (M×3, rad/m); result shape (M,)."""
    positions, weights = _validated_particles(positions_m, amplitudes)
    phi = np.atleast_2d(np.asarray(scattering_vectors_per_m, dtype=float))
    if phi.shape[1] != 3:
        raise InputError(f"scattering_vectors_per_m: must have shape (M, 3), got {phi.shape}")
    coherence = pair_coherence(positions, frame, sigma_m2, distance_m, wavelength_m, coefficients)
    pair_weight = coherence * np.outer(weights, weights)
    # (p_l − p_j)·φ = p_l·φ − p_j·φ: expand the cosine to keep memory at O(N·M + N²).
    phase = positions @ phi.T  # [j, m] = p_j·φ_m
    cos_phase, sin_phase = np.cos(phase), np.sin(phase)
    return np.einsum("jm,jl,lm->m", cos_phase, pair_weight, cos_phase) + np.einsum(
        "jm,jl,lm->m", sin_phase, pair_weight, sin_phase
    )


def angular_coherence_coefficients(
    positions_m: np.ndarray,
    amplitudes: np.ndarray,
    frame: tuple[Sequence[float], Sequence[float]],
    theta_per_m2: Sequence[Sequence[float]],
    max_order: int,
) -> dict[tuple[int, int], complex]:
    """Eq. (21) (single-sum form, module docstring): ⟨f̃_σ|Ψ̃^Θ_nm(Qζ)⟩ for every n + m ≤ ``max_order``.

    ``theta_per_m2``: the 2×2 shape matrix Θ (1/m², the frequency-domain scale of the dual functions).
    """
    positions, weights = _validated_particles(positions_m, amplitudes)
    theta = np.asarray(theta_per_m2, dtype=float)
    if theta.shape != (2, 2) or not np.allclose(theta, theta.T) or np.any(np.linalg.eigvalsh(theta) <= 0.0):
        raise InputError("theta_per_m2: must be a symmetric positive-definite 2×2 matrix")
    axis_1, axis_2 = (np.asarray(axis, dtype=float) for axis in frame)
    projected = [positions @ axis_1, positions @ axis_2]
    primal = hg_functions(projected, np.linalg.inv(theta).tolist(), max_order, NUMPY)
    intensity = weights * weights
    return {
        (n, m): complex(2.0 * math.pi * (-1j) ** (n + m) * np.sum(intensity * values))
        for (n, m), values in primal.items()
    }
