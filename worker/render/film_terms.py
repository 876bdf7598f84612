"""Thin-film reflectance split into terms linear in the visibilities (Eq. 18, P beams).

R(V) = Σ_{p,q} a_p a_q* V_{|p−q|} = R_incoherent + 2 Σ_{d≥1} V_d X_d with R_incoherent = Σ_p |a_p|² and
X_d = Σ_p Re(a_{p+d} a_p*), averaged over s and p polarisation. The integrator keeps these terms when it
samples a direction off a film and applies the visibilities once the incident coherence is known.
"""

from __future__ import annotations

import math
from typing import Any

from worker.optics.array_ops import ArrayOps
from worker.optics.complex_pair import ComplexPair
from worker.optics.fresnel import interface_amplitudes, normal_factor
from worker.optics.thin_film import beam_amplitudes


def film_amplitudes(
    cos_theta_i: Any,
    wavelength_m: Any,
    thickness_m: Any,
    film_ior: Any,
    substrate_eta: ComplexPair,
    exterior_ior: Any,
    beam_count: int,
    ops: ArrayOps,
) -> tuple[list[ComplexPair], list[ComplexPair]]:
    """Beam amplitudes (s, p) a_0 … a_{P−1} of a film of thickness τ (m) and index n_f on a substrate."""
    cos_i = ops.minimum(ops.abs(cos_theta_i), 1.0)
    invariant_sq = exterior_ior * exterior_ior * (1.0 - cos_i * cos_i)
    q_0 = ComplexPair.real(exterior_ior * cos_i)
    q_1 = normal_factor(film_ior, invariant_sq, ops)
    q_2 = normal_factor(substrate_eta, invariant_sq, ops)
    top = interface_amplitudes(exterior_ior, q_0, film_ior, q_1)
    bottom = interface_amplitudes(film_ior, q_1, substrate_eta, q_2)
    film_phase = ComplexPair.exp_i(q_1 * (2.0 * (2.0 * math.pi / wavelength_m) * thickness_m), ops)
    return (
        beam_amplitudes(top.r_s, bottom.r_s, film_phase, beam_count),
        beam_amplitudes(top.r_p, bottom.r_p, film_phase, beam_count),
    )


def reflectance_terms(amplitudes: tuple[list[ComplexPair], list[ComplexPair]]) -> list[Any]:
    """[R_incoherent, X_1, …, X_{P−1}], unpolarised (mean of s and p)."""
    terms: list[Any] = []
    for separation in range(len(amplitudes[0])):
        total: Any = 0.0
        for beams in amplitudes:
            for p in range(len(beams) - separation):
                later, earlier = beams[p + separation], beams[p]
                total = total + 0.5 * (later.re * earlier.re + later.im * earlier.im)
        terms.append(total)
    return terms
