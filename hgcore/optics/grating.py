"""Diffraction gratings under partially-coherent light: Eqs. (19)–(20) read per diffraction lobe.

Frame: local shading frame, z = normal, the grating period along x (the tangent) and, for 2-D gratings,
along y; β = (x, y) direction cosines; ω_i points towards the light, ω_o towards the viewer. λ is the vacuum
wavelength in m (the exterior medium is air).

Lobe directions (grating equation, the Poisson sum of Eq. (19)): order (p, q) leaves at
β_pq = −β_i + λ (p/Λ_x, q/Λ_y) and propagates iff |β_pq| < 1.

Order efficiencies of a binary phase profile (duty cycle D, pit depth d, index n_pit of the medium filling the
pit, read in reflection): φ_0 = 4π n_pit d/λ, η_0 = 1 − 2D(1−D)(1 − cos φ_0) and, for p ≠ 0,
η_p = 2(1 − cos φ_0) sin²(πpD)/(πp)²; Parseval gives Σ_p η_p = 1. 2-D gratings use the product η_pq = η_p η_q
of the 1-D factors (a separable pit profile); 1-D gratings have η_q = δ_q0.

Lobe shape (Eq. (20) read per lobe): Eq. (19)'s Poisson sum turns the FT of R_σσ·Ψ' into a sum of copies of
the FT of the incident CSD centred on the lattice frequencies G_pq, each convolved with the intrinsic lobe PSD
(finite illuminated patch, pit jitter). By Eq. (9) the FT of the 0th-mode CSD Ψ^{Θ'}(kQ'ξ/s) is a
Gaussian in φ⊥ with covariance (k/s)²Σ' (Σ' the incident transverse covariance projected on the surface, m²;
s the distance to the incident light's source). In β = φ⊥/k units the lobe of order (p, q) is the normalised
Gaussian N(β_o; β_pq, C_β) with C_β = Σ'/s² + (w/k)² I: ``source_angular_cov`` = Σ'/s² (rad²,
dimensionless) and w = ``lobe_width_per_um`` (rad/µm, the std of the intrinsic lobe in φ⊥). Hence

    f(ω_i, ω_o) = F(θ_i) Σ_{(p,q) ≠ 0, propagating} η_pq(λ) N(β_o; β_pq, C_β)     [1/sr]

(∫ f cos θ_o dω_o = ∫ f d²β_o, so each order keeps the energy F η_pq while its peak F η_pq/(2π√|C_β|) falls as
the source grows: the dimmed secondary lobes of Fig. 1(f); under full coherence, Σ' → 0, the peak is the
intrinsic one). The literal product S(φ⊥)·Ψ̃(φ⊥) would instead attenuate lobes *more* under *more* coherence.
The 0th order is a specular delta of efficiency η_00 that keeps the incident coherence (the caller's).

With several incident modes (whitened coefficients ĉ_nm of ``hgcore.optics.coherence``, ``film.modes``)
the source's image is the FT of the modal degree of coherence,
(1/2π|Σ'/s²|^{½}) Σ ĉ_nm (−1)^{(n+m)/2} h_n(x₁) h_m(x₂),
with x the Σ'/s²-whitened offset in its principal frame (eigenvalues λ_i), and the lobe is that image
convolved with the intrinsic Gaussian N(0, t I), t = (w/k)². The convolution is exact mode by mode: per axis,
with q = λ + t, 1/σ = √(λ/q), ρ = t/q and y = β/√q (from the generating function of the Hermite
polynomials, e^{2xu − u²} = Σ H_n(x) uⁿ/n!),

    h_n(·/√λ) ⊛ N(0, t) = (1/σ) Σ_{j ≤ n/2} (1/σ)^{n−2j} ρ^j 2^{−j} √(n!/(n−2j)!)/j! · h_{n−2j}(y),

so the lobe is (1/2π√(q₁q₂)) Σ_kl e_kl h_k(y₁) h_l(y₂) with blurred coefficients e_kl. One mode, ĉ_00 = √π,
gives N(β_o; β_pq, C_β) exactly; a point source (λ → 0) gives μ(0)·N(0, tI). The only error is the
truncation of the source's expansion (the 16-mode disk image: tests/optics/test_grating.py measures it
against a direct quadrature of the uniform disk blurred by the intrinsic lobe). A truncated expansion can
dip below zero in its tails; the lobe is clamped at 0, which adds up to 5 % to a lobe's energy (16 disk
modes at the DVD's intrinsic width; tests).
Formulas run element-wise against ``ops`` (NumPy and Dr.Jit).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hgcore.errors import InputError
from hgcore.optics.array_ops import ArrayOps, hermite_functions
from hgcore.optics.coherence import max_degree, principal_axes_components
from hgcore.optics.rough_surface import hemisphere_direction

METRES_PER_MICRON = 1e-6


@dataclass(frozen=True)
class BinaryGrating:
    """A reflective binary phase grating: pitches (m), duty cycle, pit depth (m), pit index, lobe width."""

    pitch_x_m: float
    pitch_y_m: float | None = None
    duty_cycle: float = 0.5
    depth_m: float = 110e-9
    pit_ior: float = 1.55
    lobe_width_per_um: float = 0.05
    max_order: int = 8

    def __post_init__(self) -> None:
        for name in ("pitch_x_m", "depth_m", "lobe_width_per_um"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"{name}: must be finite and > 0, got {value}")
        if self.pitch_y_m is not None and not (math.isfinite(self.pitch_y_m) and self.pitch_y_m > 0.0):
            raise InputError(
                f"pitch_y_m: must be finite and > 0 (or None for a 1-D grating), got {self.pitch_y_m}"
            )
        if not 0.0 < self.duty_cycle < 1.0:
            raise InputError(f"duty_cycle: must lie in (0, 1), got {self.duty_cycle}")
        if not (math.isfinite(self.pit_ior) and self.pit_ior >= 1.0):
            raise InputError(f"pit_ior: must be a finite real index ≥ 1, got {self.pit_ior}")
        if not 1 <= self.max_order <= 32:
            raise InputError(f"max_order: must lie in 1..32, got {self.max_order}")

    def orders(self) -> list[tuple[int, int]]:
        """All non-zero orders (p, q) with |p|, |q| ≤ max_order (q = 0 only for a 1-D grating)."""
        q_range = range(-self.max_order, self.max_order + 1) if self.pitch_y_m is not None else range(1)
        return [
            (p, q) for p in range(-self.max_order, self.max_order + 1) for q in q_range if (p, q) != (0, 0)
        ]


# Compact disc: track pitch 1.6 µm (IEC 60908:1999, "Red Book"); pits ≈ λ/(4n) deep for the 780 nm read
# laser in polycarbonate (n ≈ 1.55), i.e. ≈ 110–125 nm (K. C. Pohlmann, Principles of Digital Audio, 6th ed.,
# 2011, ch. 7; J. Bouwhuis et al., Principles of Optical Disc Systems, 1985).
CD_GRATING = BinaryGrating(pitch_x_m=1.6e-6, duty_cycle=0.5, depth_m=110e-9, pit_ior=1.55)
# DVD: track pitch 0.74 µm (ECMA-267, 3rd ed., 2001); pit depth ≈ λ/(4n) ≈ 105 nm for the 650 nm read laser
# in polycarbonate (J. Taylor, M. Johnson & C. Crawford, DVD Demystified, 3rd ed., McGraw-Hill, 2006).
DVD_GRATING = BinaryGrating(pitch_x_m=0.74e-6, duty_cycle=0.5, depth_m=105e-9, pit_ior=1.55)


def order_efficiency_1d(order: int, duty_cycle: float, cos_phase_depth: Any) -> Any:
    """η_p of a 1-D binary phase grating given cos φ_0 (dimensionless); Σ_p η_p = 1."""
    if order == 0:
        return 1.0 - 2.0 * duty_cycle * (1.0 - duty_cycle) * (1.0 - cos_phase_depth)
    sinc_factor = math.sin(math.pi * order * duty_cycle) / (math.pi * order)
    return 2.0 * (1.0 - cos_phase_depth) * sinc_factor * sinc_factor


def phase_depth_cosine(grating: BinaryGrating, wavelength_m: Any, ops: ArrayOps) -> Any:
    """cos φ_0 with φ_0 = 4π n_pit d / λ (round trip through the pit)."""
    return ops.cos(4.0 * math.pi * grating.pit_ior * grating.depth_m / wavelength_m)


def order_efficiency(grating: BinaryGrating, order: tuple[int, int], cos_phase_depth: Any) -> Any:
    """η_pq (product of the 1-D factors; a 1-D grating only has q = 0)."""
    p, q = order
    efficiency = order_efficiency_1d(p, grating.duty_cycle, cos_phase_depth)
    if grating.pitch_y_m is not None:
        efficiency = efficiency * order_efficiency_1d(q, grating.duty_cycle, cos_phase_depth)
    return efficiency


def specular_efficiency(grating: BinaryGrating, wavelength_m: Any, ops: ArrayOps) -> Any:
    """η_00: the fraction of F(θ_i) in the specular (delta) order, which keeps the incident coherence."""
    return order_efficiency(grating, (0, 0), phase_depth_cosine(grating, wavelength_m, ops))


def lobe_centre(
    grating: BinaryGrating, order: tuple[int, int], wi: Any, wavelength_m: Any
) -> tuple[Any, Any]:
    """β_pq = −β_i + λ(p/Λ_x, q/Λ_y) (grating equation)."""
    p, q = order
    centre_x = -wi[0] + wavelength_m * (p / grating.pitch_x_m)
    centre_y = -wi[1] + (wavelength_m * (q / grating.pitch_y_m) if grating.pitch_y_m is not None else 0.0)
    return centre_x, centre_y


def intrinsic_variance(grating: BinaryGrating, wavelength_m: Any) -> Any:
    """t = (w/k)²: the variance (per axis, in β², dimensionless) of the intrinsic lobe at ``wavelength_m``."""
    intrinsic_per_m = grating.lobe_width_per_um / METRES_PER_MICRON
    intrinsic_beta = intrinsic_per_m * wavelength_m / (2.0 * math.pi)
    return intrinsic_beta * intrinsic_beta


def lobe_covariance(
    grating: BinaryGrating, source_angular_cov: tuple[Any, Any, Any], wavelength_m: Any
) -> tuple[Any, Any, Any]:
    """C_β = Σ'/s² + (w/k)² I as entries (C_xx, C_xy, C_yy), dimensionless."""
    intrinsic_var = intrinsic_variance(grating, wavelength_m)
    cov_xx, cov_xy, cov_yy = source_angular_cov
    return cov_xx + intrinsic_var, cov_xy, cov_yy + intrinsic_var


def gaussian_density(dx: Any, dy: Any, covariance: tuple[Any, Any, Any], ops: ArrayOps) -> Any:
    """Normalised 2-D Gaussian N(d; 0, C) at offset (dx, dy) per unit d²β."""
    c_xx, c_xy, c_yy = covariance
    determinant = c_xx * c_yy - c_xy * c_xy
    quadratic = (c_yy * dx * dx - 2.0 * c_xy * dx * dy + c_xx * dy * dy) / determinant
    return ops.exp(-0.5 * quadratic) / (2.0 * math.pi * ops.sqrt(determinant))


def blurred_mode_factors(degree: int, inverse_sigma: Any, rho: Any) -> list[list[tuple[int, Any]]]:
    """Per n ≤ ``degree``, the (k, (1/σ)^k ρ^j 2^{−j} √(n!/k!)/j!) with k = n − 2j: h_n blurred by the
    intrinsic Gaussian along one axis as a sum of h_k(y) (module docstring; the common factor 1/σ left
    out)."""
    factors: list[list[tuple[int, Any]]] = []
    for n in range(degree + 1):
        terms = []
        for j in range(n // 2 + 1):
            k = n - 2 * j
            constant = math.sqrt(math.factorial(n) / math.factorial(k)) / (math.factorial(j) * 2.0**j)
            terms.append((k, constant * inverse_sigma**k * rho**j))
        factors.append(terms)
    return factors


class ModalLobe:
    """The lobe shape of a multi-mode source per unit d²β, centred at 0: the source's modal image (Σ'/s²,
    coefficients ĉ_nm) convolved with the intrinsic N(0, tI) (module docstring). Built once per wavelength;
    ``density`` is evaluated per order."""

    def __init__(
        self,
        source_angular_cov: tuple[Any, Any, Any],
        intrinsic_var: Any,
        coefficients: Mapping[tuple[int, int], Any],
        ops: ArrayOps,
    ) -> None:
        self.ops = ops
        lambda_major, lambda_minor, self.cos_phi, self.sin_phi = principal_axes_components(
            *source_angular_cov, ops
        )
        # Σ' = 0 (plane waves) makes λ₂ = 0/0; a rank-one Σ' can round to det < 0: both are λ₂ = 0.
        lambda_major = ops.maximum(lambda_major, 0.0)
        lambda_minor = ops.where(lambda_major > 0.0, ops.maximum(lambda_minor, 0.0), 0.0)
        q_major, q_minor = lambda_major + intrinsic_var, lambda_minor + intrinsic_var
        self.inv_sqrt_q = (1.0 / ops.sqrt(q_major), 1.0 / ops.sqrt(q_minor))
        self.scale = 1.0 / (2.0 * math.pi * ops.sqrt(q_major * q_minor))
        self.degree = max_degree(coefficients)
        major = blurred_mode_factors(self.degree, ops.sqrt(lambda_major / q_major), intrinsic_var / q_major)
        minor = blurred_mode_factors(self.degree, ops.sqrt(lambda_minor / q_minor), intrinsic_var / q_minor)
        # e_kl = Σ_nm ĉ_nm (−1)^{(n+m)/2} A_nk A_ml: the FT of h_n is (−i)^n h_n, and physical CSDs carry
        # even n + m only, where (−i)^{n+m} = (−1)^{(n+m)/2}.
        blurred: dict[tuple[int, int], Any] = {}
        for (n, m), value in coefficients.items():
            signed = -value if ((n + m) // 2) % 2 else value
            for k, factor_major in major[n]:
                for ell, factor_minor in minor[m]:
                    blurred[(k, ell)] = blurred.get((k, ell), 0.0) + signed * factor_major * factor_minor
        self.blurred = blurred

    def density(self, dx: Any, dy: Any) -> Any:
        """The lobe at offset (dx, dy) from its centre, per unit d²β (≥ 0)."""
        ops = self.ops
        y_major = (self.cos_phi * dx + self.sin_phi * dy) * self.inv_sqrt_q[0]
        y_minor = (self.cos_phi * dy - self.sin_phi * dx) * self.inv_sqrt_q[1]
        hermite_major = hermite_functions(y_major, self.degree, ops)
        hermite_minor = hermite_functions(y_minor, self.degree, ops)
        total: Any = 0.0
        for (k, ell), value in self.blurred.items():
            total = total + value * hermite_major[k] * hermite_minor[ell]
        return ops.maximum(total, 0.0) * self.scale


def _propagating_lobes(
    grating: BinaryGrating, wi: Any, wavelength_m: Any, ops: ArrayOps
) -> list[tuple[Any, Any, Any]]:
    """(centre_x, centre_y, η_pq masked to 0 when the lobe centre is evanescent) for every order ≠ 0."""
    cos_phase_depth = phase_depth_cosine(grating, wavelength_m, ops)
    lobes = []
    for order in grating.orders():
        centre_x, centre_y = lobe_centre(grating, order, wi, wavelength_m)
        propagating = centre_x * centre_x + centre_y * centre_y < 1.0
        efficiency = ops.where(propagating, order_efficiency(grating, order, cos_phase_depth), 0.0)
        lobes.append((centre_x, centre_y, efficiency))
    return lobes


def _mixture_density(
    grating: BinaryGrating,
    wi: Any,
    wo: Any,
    wavelength_m: Any,
    source_angular_cov: tuple[Any, Any, Any],
    ops: ArrayOps,
    coefficients: Mapping[tuple[int, int], Any] | None,
) -> tuple[Any, Any]:
    """(Σ η_pq N(β_o; β_pq, C_β), Σ η_pq) over propagating non-zero orders; with ``coefficients`` (several
    modes) each lobe is the ``ModalLobe`` instead of the Gaussian."""
    covariance = lobe_covariance(grating, source_angular_cov, wavelength_m)
    modal = (
        None
        if coefficients is None
        else ModalLobe(source_angular_cov, intrinsic_variance(grating, wavelength_m), coefficients, ops)
    )
    weighted_density: Any = 0.0
    total_efficiency: Any = 0.0
    for centre_x, centre_y, efficiency in _propagating_lobes(grating, wi, wavelength_m, ops):
        dx, dy = wo[0] - centre_x, wo[1] - centre_y
        density = gaussian_density(dx, dy, covariance, ops) if modal is None else modal.density(dx, dy)
        weighted_density = weighted_density + efficiency * density
        total_efficiency = total_efficiency + efficiency
    return weighted_density, total_efficiency


def grating_eval(
    grating: BinaryGrating,
    wi: Any,
    wo: Any,
    wavelength_m: Any,
    reflectance: Any,
    source_angular_cov: tuple[Any, Any, Any],
    ops: ArrayOps,
    coefficients: Mapping[tuple[int, int], Any] | None = None,
) -> Any:
    """Diffracted BRDF f [1/sr] (non-specular orders, without cos θ_o); ``reflectance`` = F(θ_i)."""
    weighted_density, _ = _mixture_density(
        grating, wi, wo, wavelength_m, source_angular_cov, ops, coefficients
    )
    return ops.where((wi[2] > 0.0) & (wo[2] > 0.0), reflectance * weighted_density, 0.0)


def grating_pdf(
    grating: BinaryGrating,
    wi: Any,
    wo: Any,
    wavelength_m: Any,
    source_angular_cov: tuple[Any, Any, Any],
    ops: ArrayOps,
    coefficients: Mapping[tuple[int, int], float] | None = None,
) -> Any:
    """Solid-angle density of :func:`grating_sample`: (Σ η_pq N_pq / Σ η_pq) cos θ_o."""
    weighted_density, total_efficiency = _mixture_density(
        grating, wi, wo, wavelength_m, source_angular_cov, ops, coefficients
    )
    valid = (wi[2] > 0.0) & (wo[2] > 0.0) & (total_efficiency > 0.0)
    safe_total = ops.where(total_efficiency > 0.0, total_efficiency, 1.0)
    return ops.where(valid, weighted_density / safe_total * wo[2], 0.0)


def grating_sample(
    grating: BinaryGrating,
    wi: Any,
    wavelength_m: Any,
    source_angular_cov: tuple[Any, Any, Any],
    u_order: Any,
    u1: Any,
    u2: Any,
    ops: ArrayOps,
) -> tuple[tuple[Any, Any, Any], Any, Any, Any]:
    """Sample a diffracted direction (0th-mode lobes): ``(wo, pdf_solid_angle, valid, order_weight)``.

    An order is chosen ∝ η_pq among propagating orders (``u_order``), then β_o ~ N(β_pq, C_β) by Box–Muller
    with the Cholesky factor of C_β (``u1, u2``). ``order_weight`` = Σ η_pq: the sample weight
    f cos θ_o / pdf equals F(θ_i)·order_weight. Invalid when no order propagates or |β_o| ≥ 1.
    """
    lobes = _propagating_lobes(grating, wi, wavelength_m, ops)
    total_efficiency: Any = 0.0
    for _, _, efficiency in lobes:
        total_efficiency = total_efficiency + efficiency
    target = u_order * total_efficiency
    cumulative: Any = 0.0
    cumulative_values = []
    for _, _, efficiency in lobes:
        cumulative = cumulative + efficiency
        cumulative_values.append(cumulative)
    # Walk the orders backwards so that the *first* order whose cumulative mass exceeds the target wins.
    chosen_x: Any = lobes[-1][0]
    chosen_y: Any = lobes[-1][1]
    for (centre_x, centre_y, _), upper in zip(reversed(lobes), reversed(cumulative_values), strict=True):
        chosen_x = ops.where(target < upper, centre_x, chosen_x)
        chosen_y = ops.where(target < upper, centre_y, chosen_y)
    c_xx, c_xy, c_yy = lobe_covariance(grating, source_angular_cov, wavelength_m)
    radius = ops.sqrt(-2.0 * ops.log(1.0 - u1))
    angle = 2.0 * math.pi * u2
    z_1, z_2 = radius * ops.cos(angle), radius * ops.sin(angle)
    l_11 = ops.sqrt(c_xx)
    l_21 = c_xy / l_11
    l_22 = ops.sqrt(ops.maximum(c_yy - l_21 * l_21, 0.0))
    beta_x = chosen_x + l_11 * z_1
    beta_y = chosen_y + l_21 * z_1 + l_22 * z_2
    beta_sq = beta_x * beta_x + beta_y * beta_y
    valid = (beta_sq < 1.0) & (wi[2] > 0.0) & (total_efficiency > 0.0)
    wo = hemisphere_direction(beta_x, beta_y, valid, ops)
    pdf = ops.where(valid, grating_pdf(grating, wi, wo, wavelength_m, source_angular_cov, ops), 0.0)
    return wo, pdf, valid, total_efficiency
