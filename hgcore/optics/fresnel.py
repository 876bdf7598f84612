"""Fresnel amplitude and power coefficients of a planar interface, for dielectrics and conductors.

Conventions (Born & Wolf §1.5, Hecht "Optics" §4.6): fields vary as e^{i(k·r − ωt)}, a lossy medium has the
complex index η = n + iκ with κ ≥ 0. Snell's law conserves the tangential invariant ν = n_0 sin θ_0 across a
stack of layers, so every layer is described by its normal factor q = η cos θ = √(η² − ν²) (principal branch:
Im q ≥ 0, an absorbed or evanescent wave decays away from the interface). With q_i, q_t of the two sides

    r_s = (q_i − q_t)/(q_i + q_t),            t_s = 2 q_i/(q_i + q_t),
    r_p = (η_t² q_i − η_i² q_t)/(η_t² q_i + η_i² q_t),   t_p = 2 η_i η_t q_i/(η_t² q_i + η_i² q_t),

which are Hecht's r_⊥, t_⊥, r_∥, t_∥ (electric-field amplitudes; r_p = −r_s at normal incidence). They obey
the Stokes relations r_ti = −r_it and t_it·t_ti = 1 − r_it², which the thin-film sum relies on. All quantities
are dimensionless; every formula is element-wise against ``ops`` so it runs on NumPy and inside Dr.Jit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hgcore.optics.array_ops import ArrayOps
from hgcore.optics.complex_pair import ComplexPair


@dataclass(frozen=True)
class InterfaceAmplitudes:
    """Complex s- and p-polarised amplitude coefficients of one interface (dimensionless)."""

    r_s: ComplexPair
    r_p: ComplexPair
    t_s: ComplexPair
    t_p: ComplexPair


def normal_factor(eta: Any, tangential_invariant_sq: Any, ops: ArrayOps) -> ComplexPair:
    """q = η cos θ = √(η² − ν²) of a layer of index ``eta`` (real or ``ComplexPair``); ν² = (n_0 sin θ_0)²."""
    eta_c = ComplexPair.lift(eta)
    return (eta_c * eta_c - tangential_invariant_sq).sqrt(ops)


def interface_amplitudes(eta_i: Any, q_i: ComplexPair, eta_t: Any, q_t: ComplexPair) -> InterfaceAmplitudes:
    """Amplitude coefficients from side i (index ``eta_i``, normal factor ``q_i``) into side t.

    ``eta_*`` may be real arrays or ``ComplexPair``; ``q_*`` come from :func:`normal_factor`.
    """
    eta_i_c = ComplexPair.lift(eta_i)
    eta_t_c = ComplexPair.lift(eta_t)
    s_denominator = q_i + q_t
    eta_t_sq_q_i = eta_t_c * eta_t_c * q_i
    eta_i_sq_q_t = eta_i_c * eta_i_c * q_t
    p_denominator = eta_t_sq_q_i + eta_i_sq_q_t
    return InterfaceAmplitudes(
        r_s=(q_i - q_t) / s_denominator,
        r_p=(eta_t_sq_q_i - eta_i_sq_q_t) / p_denominator,
        t_s=(2.0 * q_i) / s_denominator,
        t_p=(2.0 * eta_i_c * eta_t_c * q_i) / p_denominator,
    )


def fresnel_reflectance(cos_theta_i: Any, eta: Any, ops: ArrayOps) -> Any:
    """Unpolarised power reflectance R = (|r_s|² + |r_p|²)/2 of an interface.

    ``eta`` is the relative index η_t/η_i: a real array for a dielectric (η < 1 gives total internal
    reflection beyond the critical angle, R = 1) or a ``ComplexPair`` n + iκ for a conductor.
    ``cos_theta_i`` is taken by magnitude (either side of the surface).
    """
    cos_i = ops.minimum(ops.abs(cos_theta_i), 1.0)
    invariant_sq = 1.0 - cos_i * cos_i
    q_i = ComplexPair.real(cos_i)
    q_t = normal_factor(eta, invariant_sq, ops)
    amplitudes = interface_amplitudes(1.0, q_i, eta, q_t)
    return 0.5 * (amplitudes.r_s.abs2() + amplitudes.r_p.abs2())


def fresnel_dielectric(cos_theta_i: Any, eta: Any, ops: ArrayOps) -> tuple[Any, Any]:
    """Reflectance R and refracted |cos θ_t| for a real relative index ``eta`` = n_t/n_i.

    Returns ``(R, cos_theta_t)``; the transmitted power fraction is T = 1 − R (lossless interface), and
    cos θ_t = 0 under total internal reflection (R = 1). Snell: sin θ_t = sin θ_i / η.
    """
    cos_i = ops.minimum(ops.abs(cos_theta_i), 1.0)
    sin_t_sq = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = ops.sqrt(ops.maximum(1.0 - sin_t_sq, 0.0))
    # The complex-q path of fresnel_reflectance already yields |r| = 1 under total internal reflection.
    return fresnel_reflectance(cos_i, eta, ops), cos_t
