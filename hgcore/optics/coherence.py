"""Coherence of a beam from its transverse covariance: shape matrix, diagnostics and degree of coherence.

Conventions (docs/physics.md):

* Def. 4.1: C(ξ) ∝ Σ_nm c_nm Ψ^Θ_nm(k/r · Qξ) with Θ⁻¹ = Σ⊥, the transverse covariance (m²) of the
  (primary or secondary) source's intensity seen from the receiver, in the beam's local frame. Θ is in 1/m².
* Lemma 4.4 / Theorem 5.1(ii): Θ = −Qᵀ[∂²_ζ ln f̃(ζ)|₀]⁻¹Q. For f̃ = F{normalised intensity},
  −∂² ln f̃|₀ = Σ (second moments), so Θ = Σ⁻¹ is positive-definite with this sign. Numerical noise is
  repaired as in §4.1 by flipping negative eigenvalues and clipping them to ε (``make_positive_definite``).
* Diagnostics (BRIEF): M = (k/r)² Σ⊥ (1/m²) so that the 0th mode gives |μ(ξ)| = exp(−½ ξᵀMξ);
  ℓ₁ ≥ ℓ₂ = eigenvalues of M to the power −½ (1/√e half-widths); anisotropy = ℓ₁/ℓ₂; area = π ℓ₁ ℓ₂;
  angle = orientation of the ℓ₁ axis from the transverse x axis, radians in (−π/2, π/2]. Cor. 4.2's
  coherence area and anisotropy are the same quantities up to its ad-hoc cut-off factor of 2.
* Degree of coherence with N modes: μ(ξ) = Σ ĉ_nm h_n(u₁) h_m(u₂), where u = Σ^{½}-whitened k/r·ξ in the
  principal frame of Σ (u_i = √λ_i (e_i · k/r ξ), λ₁ ≥ λ₂ eigenvalues of Σ with unit eigenvectors e_i) and
  h_n are normalised 1-D Hermite functions. This is Σ c_nm Ψ^Θ_nm(k/r ξ) with the factor
  |Θ|^{-1/4} Π θ_i^{-α_i/2} of Eq. (5) folded into the universal coefficients ĉ
  (see ``hgcore.optics.sources``), so nothing over- or underflows in single precision.

Component functions (``*_components``, ``degree_of_coherence``) take scalars or arrays and an ``ops``
namespace so that they run on NumPy arrays and inside Dr.Jit kernels; matrices are passed as their entries.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY, ArrayOps, hermite_functions

DEFAULT_WAVELENGTH_M = 550e-9
METRES_TO_MICRONS = 1e6


def wavenumber_per_m(wavelength_m: Any) -> Any:
    """k = 2π/λ in 1/m."""
    return (2.0 * math.pi) / wavelength_m


def symmetric_2x2(matrix: Any, name: str) -> np.ndarray:
    """``matrix`` as a finite, symmetric float64 2×2 array; ValueError naming ``name`` otherwise."""
    array = np.asarray(matrix, dtype=float)
    if array.shape != (2, 2):
        raise InputError(f"{name}: expected a 2x2 matrix, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: entries must be finite, got {array.tolist()}")
    scale = float(np.max(np.abs(array)))
    if abs(array[0, 1] - array[1, 0]) > 1e-9 * max(scale, 1e-300):
        raise InputError(f"{name}: must be symmetric, got {array.tolist()}")
    return 0.5 * (array + array.T)


def make_positive_definite(matrix: Any, epsilon: float) -> np.ndarray:
    """The symmetric ``matrix`` with negative eigenvalues flipped and all eigenvalues clipped to ≥ ε (§4.1).

    Works for any square symmetric matrix (2×2 transverse or 3×3); units are those of ``matrix``.
    """
    if not (epsilon > 0.0 and math.isfinite(epsilon)):
        raise InputError(f"epsilon: must be a positive finite number, got {epsilon}")
    array = np.asarray(matrix, dtype=float)
    if array.ndim != 2 or array.shape[0] != array.shape[1]:
        raise InputError(f"matrix: expected a square matrix, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"matrix: entries must be finite, got {array.tolist()}")
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (array + array.T))
    repaired = np.maximum(np.abs(eigenvalues), epsilon)
    return (eigenvectors * repaired) @ eigenvectors.T


def require_positive_definite(matrix: np.ndarray, name: str) -> np.ndarray:
    """``matrix`` unchanged if symmetric positive-definite, else ValueError naming ``name``."""
    symmetric = symmetric_2x2(matrix, name) if np.shape(matrix) == (2, 2) else np.asarray(matrix, float)
    eigenvalues = np.linalg.eigvalsh(symmetric)
    if not np.all(eigenvalues > 0.0):
        raise InputError(
            f"{name}: must be positive-definite, got eigenvalues {eigenvalues.tolist()} "
            f"of {symmetric.tolist()}"
        )
    return symmetric


def shape_matrix_from_covariance(sigma_m2: Any) -> np.ndarray:
    """Θ = Σ⊥⁻¹ (1/m²) for a positive-definite transverse covariance Σ⊥ (m²)."""
    return np.linalg.inv(require_positive_definite(symmetric_2x2(sigma_m2, "sigma_m2"), "sigma_m2"))


def shape_matrix_from_log_hessian(hessian: Any, epsilon: float = 1e-300) -> np.ndarray:
    """Lemma 4.4 with its sign: Θ = −[∂²_ζ ln f̃|₀]⁻¹, repaired to be positive-definite (§4.1).

    ``hessian`` is ∂² ln f̃ at ζ = 0 (units m², ζ in 1/m); the result is in 1/m². Theorem 5.1(ii) prints the
    same formula without the minus sign; with it Θ = Σ⁻¹ > 0 for any intensity distribution.
    """
    array = np.asarray(hessian, dtype=float)
    if array.ndim != 2 or array.shape[0] != array.shape[1] or not np.all(np.isfinite(array)):
        raise InputError(f"hessian: expected a finite square matrix, got {array.tolist()}")
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (array + array.T))
    if np.any(eigenvalues == 0.0):
        raise InputError(f"hessian: singular (eigenvalues {eigenvalues.tolist()}); Θ would be infinite")
    theta = (eigenvectors * (-1.0 / eigenvalues)) @ eigenvectors.T
    return make_positive_definite(theta, epsilon)


def coherence_matrix_components(
    sigma_xx_m2: Any, sigma_xy_m2: Any, sigma_yy_m2: Any, r_m: Any, wavelength_m: Any
) -> tuple[Any, Any, Any]:
    """Entries (M_xx, M_xy, M_yy) of M = (k/r)² Σ⊥ in 1/m² (NumPy or Dr.Jit)."""
    scale = wavenumber_per_m(wavelength_m) / r_m
    scale2 = scale * scale
    return scale2 * sigma_xx_m2, scale2 * sigma_xy_m2, scale2 * sigma_yy_m2


@dataclass(frozen=True)
class DiagnosticComponents:
    """Per-sample coherence diagnostics (scalars or arrays), in the units of the BRIEF's EXR channels."""

    l1_um: Any
    l2_um: Any
    angle: Any
    anisotropy: Any
    area_um2: Any
    Mxx: Any
    Mxy: Any
    Myy: Any


def diagnostics_components(
    sigma_xx_m2: Any,
    sigma_xy_m2: Any,
    sigma_yy_m2: Any,
    r_m: Any,
    wavelength_m: Any = DEFAULT_WAVELENGTH_M,
    ops: ArrayOps = NUMPY,
) -> DiagnosticComponents:
    """ℓ₁, ℓ₂ (µm), angle (rad), anisotropy, area (µm²) and M (1/m²) from Σ⊥ entries (NumPy or Dr.Jit).

    Eigenvalues of the symmetric 2×2 M = [[a, b], [b, c]]: m₊ = (a+c)/2 + √(((a−c)/2)² + b²) and
    m₋ = (ac − b²)/m₊ (the product form avoids the cancellation of (a+c)/2 − √… for strongly anisotropic
    M in single precision). ℓ₁ = m₋^{-½} lies along the eigenvector of m₋, at angle ½·atan2(−2b, c − a)
    from the x axis; the result is wrapped from [−π/2, π/2] into (−π/2, π/2].
    """
    a, b, c = coherence_matrix_components(sigma_xx_m2, sigma_xy_m2, sigma_yy_m2, r_m, wavelength_m)
    half_difference = 0.5 * (a - c)
    m_plus = 0.5 * (a + c) + ops.sqrt(half_difference * half_difference + b * b)
    m_minus = (a * c - b * b) / m_plus
    l1_um = METRES_TO_MICRONS / ops.sqrt(m_minus)
    l2_um = METRES_TO_MICRONS / ops.sqrt(m_plus)
    angle = 0.5 * ops.atan2(-2.0 * b, c - a)
    # + 0.0 turns a −0.0 from atan2(−0.0, ·) into 0.0.
    angle = ops.where(angle <= -0.5 * math.pi, angle + math.pi, angle) + 0.0
    return DiagnosticComponents(
        l1_um=l1_um,
        l2_um=l2_um,
        angle=angle,
        anisotropy=l1_um / l2_um,
        area_um2=math.pi * l1_um * l2_um,
        Mxx=a,
        Mxy=b,
        Myy=c,
    )


@dataclass(frozen=True)
class CoherenceDiagnostics:
    """Coherence diagnostics of one beam (BRIEF definitions; lengths at ``wavelength_m``)."""

    l1_um: float
    l2_um: float
    anisotropy: float
    angle: float
    area_um2: float
    r_m: float
    wavelength_m: float
    M_per_m2: np.ndarray


def coherence_diagnostics(
    sigma_m2: Any, r_m: float, wavelength_m: float = DEFAULT_WAVELENGTH_M
) -> CoherenceDiagnostics:
    """Diagnostics of a beam with transverse covariance Σ⊥ (m², 2×2) after propagating ``r_m`` metres."""
    sigma = require_positive_definite(symmetric_2x2(sigma_m2, "sigma_m2"), "sigma_m2")
    if not (r_m > 0.0 and math.isfinite(r_m)):
        raise InputError(f"r_m: must be a positive finite distance in metres, got {r_m}")
    if not (wavelength_m > 0.0 and math.isfinite(wavelength_m)):
        raise InputError(f"wavelength_m: must be a positive finite wavelength in metres, got {wavelength_m}")
    values = diagnostics_components(sigma[0, 0], sigma[0, 1], sigma[1, 1], r_m, wavelength_m, NUMPY)
    return CoherenceDiagnostics(
        l1_um=float(values.l1_um),
        l2_um=float(values.l2_um),
        anisotropy=float(values.anisotropy),
        angle=float(values.angle),
        area_um2=float(values.area_um2),
        r_m=float(r_m),
        wavelength_m=float(wavelength_m),
        M_per_m2=np.array([[values.Mxx, values.Mxy], [values.Mxy, values.Myy]], dtype=float),
    )


def principal_axes_components(
    sigma_xx_m2: Any, sigma_xy_m2: Any, sigma_yy_m2: Any, ops: ArrayOps = NUMPY
) -> tuple[Any, Any, Any, Any]:
    """(λ₁, λ₂, cos φ, sin φ): eigenvalues λ₁ ≥ λ₂ of Σ⊥ (m²) and the angle φ of λ₁'s eigenvector.

    φ = ½·atan2(2Σ_xy, Σ_xx − Σ_yy); e₁ = (cos φ, sin φ), e₂ = (−sin φ, cos φ). λ₂ = det/λ₁ (no cancellation).
    """
    half_difference = 0.5 * (sigma_xx_m2 - sigma_yy_m2)
    root = ops.sqrt(half_difference * half_difference + sigma_xy_m2 * sigma_xy_m2)
    lambda_major = 0.5 * (sigma_xx_m2 + sigma_yy_m2) + root
    lambda_minor = (sigma_xx_m2 * sigma_yy_m2 - sigma_xy_m2 * sigma_xy_m2) / lambda_major
    phi = 0.5 * ops.atan2(2.0 * sigma_xy_m2, sigma_xx_m2 - sigma_yy_m2)
    return lambda_major, lambda_minor, ops.cos(phi), ops.sin(phi)


def positive_semidefinite_components(
    m_xx: Any, m_xy: Any, m_yy: Any, ops: ArrayOps = NUMPY
) -> tuple[Any, Any, Any]:
    """The nearest positive-semidefinite 2×2 matrix (Frobenius norm) to the symmetric (m_xx, m_xy, m_yy):
    negative eigenvalues set to 0. For estimates that are PSD in exact arithmetic but not after rounding
    (a covariance from float32 raw moments, second − mean², which cancels when the directions agree)."""
    lambda_major, lambda_minor, cos_phi, sin_phi = principal_axes_components(m_xx, m_xy, m_yy, ops)
    lambda_major = ops.where(lambda_major > 0.0, lambda_major, 0.0)
    lambda_minor = ops.where(lambda_major > 0.0, ops.maximum(lambda_minor, 0.0), 0.0)
    cos_sq, sin_sq = cos_phi * cos_phi, sin_phi * sin_phi
    return (
        lambda_major * cos_sq + lambda_minor * sin_sq,
        (lambda_major - lambda_minor) * cos_phi * sin_phi,
        lambda_major * sin_sq + lambda_minor * cos_sq,
    )


def max_degree(coefficients: Mapping[tuple[int, int], float]) -> int:
    """The largest per-axis Hermite degree used by ``coefficients``."""
    return max(max(n, m) for n, m in coefficients)


def degree_of_coherence(
    xi_m: Sequence[Any],
    sigma_m2: Sequence[Any],
    r_m: Any,
    wavelength_m: Any,
    coefficients: Mapping[tuple[int, int], float],
    ops: ArrayOps = NUMPY,
) -> Any:
    """μ(ξ) = Σ ĉ_nm h_n(u₁) h_m(u₂) for a transverse separation ξ (NumPy or Dr.Jit).

    ``xi_m`` = (ξ_x, ξ_y) in metres and ``sigma_m2`` = (Σ_xx, Σ_xy, Σ_yy) in m², both in the beam's transverse
    frame; ``r_m`` the propagation distance (m); ``coefficients`` the universal whitened-basis coefficients
    ĉ_nm of ``hgcore.optics.sources.source_coefficients`` (normalised so that μ(0) = 1). u is the whitened
    argument k/r·ξ in Σ's principal frame (module docstring). With the single coefficient ĉ₀₀ = √π this is
    exactly exp(−½ ξᵀMξ), M = (k/r)²Σ⊥ — van Cittert–Zernike for a Gaussian source.
    """
    sigma_xx, sigma_xy, sigma_yy = sigma_m2
    scale = wavenumber_per_m(wavelength_m) / r_m
    x_frequency = scale * xi_m[0]
    y_frequency = scale * xi_m[1]
    if set(coefficients) == {(0, 0)}:
        # 0th mode: ĉ₀₀ h₀(u₁)h₀(u₂) = ĉ₀₀/√π · exp(−½ xᵀΣx), no eigen-decomposition needed.
        quadratic = (
            sigma_xx * x_frequency * x_frequency
            + 2.0 * sigma_xy * x_frequency * y_frequency
            + sigma_yy * y_frequency * y_frequency
        )
        return (coefficients[(0, 0)] / math.sqrt(math.pi)) * ops.exp(-0.5 * quadratic)
    lambda_major, lambda_minor, cos_phi, sin_phi = principal_axes_components(
        sigma_xx, sigma_xy, sigma_yy, ops
    )
    # Σ⊥ = 0 (a point source; lanes that carry no coherence) makes λ₂ = 0/0, and a rank-one Σ⊥ can round
    # to det < 0 in float32: both are u = 0 along that axis (fully coherent), not NaN.
    lambda_minor = ops.where(lambda_major > 0.0, ops.maximum(lambda_minor, 0.0), 0.0)
    u_major = ops.sqrt(lambda_major) * (cos_phi * x_frequency + sin_phi * y_frequency)
    u_minor = ops.sqrt(lambda_minor) * (cos_phi * y_frequency - sin_phi * x_frequency)
    degree = max_degree(coefficients)
    hermite_major = hermite_functions(u_major, degree, ops)
    hermite_minor = hermite_functions(u_minor, degree, ops)
    total: Any = 0.0
    for (n, m), value in coefficients.items():
        total = total + value * hermite_major[n] * hermite_minor[m]
    return total
