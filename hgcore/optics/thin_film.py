"""Partially-coherent reflectance of a thin film over a substrate: Eq. (18) generalised to P beams.

Layers: exterior (real index n_0) | film (index η_f = n_f + iκ_f, thickness τ in m: real for a clear
coating, complex for an absorbing one, e.g. silver-sulfide tarnish) | substrate (η_s = n + iκ, dielectric
or conductor). With the interface amplitudes of ``hgcore.optics.fresnel`` (per polarisation) the beams
leaving the film are

    a_0 = r_01,    a_p = t_01 t_10 r_12 (r_10 r_12)^{p−1} e^{i p δ}  (p ≥ 1),    δ = 2 k q_1 τ,

with k = 2π/λ (λ the vacuum wavelength, m) and q_1 = n_f cos θ_t the film's normal factor (complex beyond the
film's critical angle, where e^{iδ} then decays). Beams p and q have travelled through the film a
different number of times; the incident light's degree of coherence between them is V_{|p−q|}, the value of
the incident HG function at the transverse part of |p−q|·s, s the lateral shear of one round trip
(:func:`film_shear`, |s| = 2τ tan θ_t; Theorem 5.1(i) with the separation of the refracted path rather than
Eq. (18)'s τẑ — docs/physics_interactions.md §3; Eq. (18) is the two-beam case
I_1 + I_2 + 2√(I_1 I_2)·V·cos(τφ_z)). The partially-coherent reflectance is

    R = Σ_{p,q<P} a_p a_q* V_{|p−q|} = Σ_p |a_p|² + 2 Σ_{d≥1} V_d Re Σ_p a_{p+d} a_p*,    V_0 = 1,

averaged over s and p polarisation (unpolarised light). V_d = 1 for all d and P → ∞ gives the Airy
formula |(r_01 + r_12 e^{iδ})/(1 + r_01 r_12 e^{iδ})|²; V_d = 0 gives the incoherent sum Σ|a_p|². The caller
supplies V_1 … V_{P−1} (dimensionless, in [0, 1]); for a 0th-mode (Gaussian) CSD they are
V_d = V_1^{d²} (:func:`gaussian_visibilities`). Element-wise against ``ops``: runs on NumPy and in Dr.Jit.

Absorbing films (κ_f > 0). Nothing above assumes a real η_f: q_1 = √(η_f² − ν²) is taken on the principal
branch (Im q_1 > 0 for κ_f > 0 at every angle), the interface amplitudes and the Stokes relations
r_10 = −r_01, t_01 t_10 = 1 − r_01² are algebraic identities of the q's and η's (``hgcore.optics.fresnel``),
and the round-trip factor e^{iδ} = e^{i 2k Re(q_1) τ}·e^{−2k Im(q_1) τ} now also carries the film's
attenuation over the round trip, so every a_p already includes the loss of its p round trips. The
reflected beams travel in the real exterior, so |a_p|² is beam p's power and R(V) keeps its meaning. Only
the transmittance changes: T = 1 − R (:func:`transmission_terms`) needs a lossless film; an absorbing film
on a dielectric is rejected (:func:`validate_thin_film`), on a conductor nothing is transmitted and the
absorptance is A = 1 − R.

All beams (:func:`film_reflectance_terms`, what the renderer uses). Truncating the series at P beams is
not bounded: near grazing incidence |r_10 r_12| → 1 on a metal, the partial sums of Σ a_p e^{ipφ} overshoot
and R exceeds 1 (7 beams on silver at 85°: R = 1.14; Eq. (18)'s two beams: up to 1.39 on silver at grazing
incidence, V = 1). The series is geometric, so every beam can be kept: with A = t_01 t_10 r_12 e^{iδ} and
b = r_10 r_12 e^{iδ} (a_p = A b^{p−1}, |b| < 1 for every absorbing or lossless stack short of exact
grazing incidence),

    R_incoherent = |r_01|² + |A|²/(1 − |b|²),
    Σ_p a_{p+d} a_p* = C b^{d−1},    C = A r_01* + |A|² b/(1 − |b|²),

per polarisation, so X_d = Re(C b^{d−1}) for every separation d ≥ 1. Derivation (valid for complex A, b,
r_01, i.e. absorbing films): Σ_{p≥1} |a_p|² = |A|² Σ_{m≥0} |b|^{2m} and Σ_{p≥1} a_{p+d} a_p* =
A b^d A* Σ_{m≥0} |b|^{2m}, plus the p = 0 term a_d r_01* = A b^{d−1} r_01*; both geometric series converge
iff |b| < 1. Absorption only helps: |b| = |r_10 r_12|·e^{−2k Im(q_1) τ} with Im q_1 > 0, and
|r_10 r_12| < 1 for passive media at the indices a scene admits (κ_f ≤ 10; checked over a grid of
absorbing films on Ag and Au, tests/optics/test_thin_film_absorbing.py). Σ_{d≥P−1} C b^{d−1} =
C b^{P−2}/(1 − b) needs the same |b| < 1. The caller knows V_1 … V_{P−1}; the
separations d ≥ P − 1 are summed together with V_{P−1}: X_{P−1} = Re(C b^{P−2}/(1 − b)). This is exact for
V ≡ 1 (the Airy formula, every P) and for V ≡ 0 (the infinite incoherent sum). On a metal the all-beam
fringes are far shallower than the truncated ones: C ∝ (1 − |r_12|²) at normal incidence, and for
|r_12| → 1 the coherent sum tends to R = 1 at every δ. For a Gaussian V_d = V_1^{d²} the tail is
over-coherent (V_{P−1} ≥ V_d for d ≥ P); its error 2 Σ_{d≥P} (V_{P−1} − V_d) X_d vanishes in both limits
and is largest for V_1 ≈ 0.9 near grazing incidence on silver (R ≤ 1.0016 over 0°–89.9°, 0.05–3 µm,
n_f 1.38–2.1, P = 3–8; tests/optics/test_thin_film.py). P = 2 stays Eq. (18) as the paper writes it, the
two-beam truncation, which scenes request explicitly to reproduce the paper (`beams: 2`); on silver its
fringe maxima exceed 1 (up to 1.26 for 1.23 µm of n_f 1.5 at V = 1, 1.39 for 0.1 µm of n_f 2.1 near
grazing incidence). :func:`bounded_reflectance` clips the all-beam residual so that R ∈ [0, 1] and
T = 1 − R ≥ 0 hold for P ≥ 3 everywhere; for P = 2 it clips at 0 only (T ≥ 0: Eq. (18) stays ≤ 1 on
glass). :func:`reflectance_terms` of :func:`film_amplitudes` is the
explicit P-beam truncation, kept as the reference the limits are tested against.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from hgcore.errors import InputError
from hgcore.optics.array_ops import ArrayOps
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import interface_amplitudes, normal_factor

#: Largest film extinction κ_f a scene may give (even metal-like absorbing coatings stay below 10).
MAX_FILM_EXTINCTION = 10.0


def gaussian_visibilities(first_visibility: Any, count: int, ops: ArrayOps) -> list[Any]:
    """V_1 … V_count for a Gaussian degree of coherence: V_d = exp(−½ d² ξᵀMξ) = V_1^{d²}.

    Built by V_{d+1} = V_d · V_1^{2d+1} so that no powers or logarithms of V_1 are formed.
    """
    if count < 0:
        raise InputError(f"count: must be non-negative, got {count}")
    visibilities: list[Any] = []
    current = first_visibility
    odd_power = first_visibility  # V_1^{2d+1}, starting at d = 0
    v1_squared = first_visibility * first_visibility
    for _ in range(count):
        visibilities.append(current)
        odd_power = odd_power * v1_squared
        current = current * odd_power
    return visibilities


def beam_amplitudes(
    r_01: ComplexPair, r_12: ComplexPair, film_phase: ComplexPair, beam_count: int
) -> list[ComplexPair]:
    """a_0 … a_{P−1} of one polarisation, using the Stokes relations r_10 = −r_01, t_01 t_10 = 1 − r_01²."""
    amplitudes = [r_01]
    if beam_count < 2:
        return amplitudes
    round_trip = film_phase * r_12
    amplitudes.append((1.0 - r_01 * r_01) * round_trip)
    bounce = -(r_01 * round_trip)  # r_10 r_12 e^{iδ}
    for _ in range(2, beam_count):
        amplitudes.append(amplitudes[-1] * bounce)
    return amplitudes


def _film_interfaces(
    cos_theta_i: Any,
    wavelength_m: Any,
    thickness_m: Any,
    film_ior: Any,
    substrate_eta: ComplexPair,
    exterior_ior: Any,
    ops: ArrayOps,
) -> tuple[Any, Any, ComplexPair]:
    """The film's top and bottom interface amplitudes (``fresnel.interface_amplitudes``) and the round-trip
    phase factor e^{iδ}, δ = 2 k q_1 τ (arguments as in :func:`film_amplitudes`)."""
    cos_i = ops.minimum(ops.abs(cos_theta_i), 1.0)
    invariant_sq = exterior_ior * exterior_ior * (1.0 - cos_i * cos_i)
    q_0 = ComplexPair.real(exterior_ior * cos_i)
    q_1 = normal_factor(film_ior, invariant_sq, ops)
    q_2 = normal_factor(substrate_eta, invariant_sq, ops)
    top = interface_amplitudes(exterior_ior, q_0, film_ior, q_1)
    bottom = interface_amplitudes(film_ior, q_1, substrate_eta, q_2)
    wavenumber_per_m = 2.0 * math.pi / wavelength_m
    film_phase = ComplexPair.exp_i(q_1 * (2.0 * wavenumber_per_m * thickness_m), ops)
    return top, bottom, film_phase


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
    """Beam amplitudes (s, p) a_0 … a_{P−1} of a film of thickness τ (m) and index n_f on a substrate.

    ``cos_theta_i`` is the cosine of the angle of incidence in the exterior medium (taken by magnitude);
    ``substrate_eta`` the substrate's complex index (``ComplexPair``; κ = 0 for a dielectric), ``film_ior``
    the film's index, real or a ``ComplexPair`` n_f + iκ_f for an absorbing film (module docstring).
    """
    top, bottom, film_phase = _film_interfaces(
        cos_theta_i, wavelength_m, thickness_m, film_ior, substrate_eta, exterior_ior, ops
    )
    return (
        beam_amplitudes(top.r_s, bottom.r_s, film_phase, beam_count),
        beam_amplitudes(top.r_p, bottom.r_p, film_phase, beam_count),
    )


def reflectance_terms(amplitudes: tuple[list[ComplexPair], list[ComplexPair]]) -> list[Any]:
    """[R_incoherent, X_1, …, X_{P−1}], unpolarised (mean of s and p).

    R(V) = Σ_{p,q} a_p a_q* V_{|p−q|} = R_incoherent + 2 Σ_{d≥1} V_d X_d is linear in the visibilities, with
    R_incoherent = Σ_p |a_p|² and X_d = Σ_p Re(a_{p+d} a_p*); an integrator can keep these terms and apply
    the visibilities once the incident coherence is known.
    """
    terms: list[Any] = []
    for separation in range(len(amplitudes[0])):
        total: Any = 0.0
        for beams in amplitudes:
            for p in range(len(beams) - separation):
                later, earlier = beams[p + separation], beams[p]
                total = total + 0.5 * (later.re * earlier.re + later.im * earlier.im)
        terms.append(total)
    return terms


def film_reflectance_terms(
    cos_theta_i: Any,
    wavelength_m: Any,
    thickness_m: Any,
    film_ior: Any,
    substrate_eta: ComplexPair,
    exterior_ior: Any,
    beam_count: int,
    ops: ArrayOps,
) -> list[Any]:
    """[R_incoherent, X_1, …, X_{P−1}] of the film with *every* beam (module docstring: "All beams"),
    unpolarised, for ``beam_count`` = P ≥ 3: X_{P−1} holds all separations d ≥ P − 1. Arguments as in
    :func:`film_amplitudes` (``film_ior`` real or complex); combine with V_1 … V_{P−1}
    (:func:`bounded_reflectance`): exact Airy for V ≡ 1, the infinite incoherent sum for V ≡ 0. P = 2 is
    Eq. (18) itself, the paper's two-beam truncation (:func:`reflectance_terms` of two beams), which a
    scene asks for explicitly.
    """
    if beam_count <= 2:
        # Eq. (18) as the paper writes it: the scene asked for the two-beam truncation
        amplitudes = film_amplitudes(
            cos_theta_i, wavelength_m, thickness_m, film_ior, substrate_eta, exterior_ior, beam_count, ops
        )
        return reflectance_terms(amplitudes)
    top, bottom, film_phase = _film_interfaces(
        cos_theta_i, wavelength_m, thickness_m, film_ior, substrate_eta, exterior_ior, ops
    )
    terms: list[Any] = [0.0] * beam_count
    for r_01, r_12 in ((top.r_s, bottom.r_s), (top.r_p, bottom.r_p)):
        first = (1.0 - r_01 * r_01) * (film_phase * r_12)  # A = t01 t10 r12 e^{iδ}
        bounce = -(r_01 * (film_phase * r_12))  # b = r10 r12 e^{iδ}
        first_sq = first.abs2()
        # 1 − |b|² > 0 for every absorbing or lossless stack short of exact grazing incidence
        remaining = ops.maximum(1.0 - bounce.abs2(), 1e-30)
        later_sq = first_sq / remaining  # Σ_{p≥1} |a_p|²
        # X_d = Re(C b^{d−1}), C = A r01* + |A|² b/(1 − |b|²)
        coefficient = first * r_01.conj() + bounce * later_sq
        terms[0] = terms[0] + 0.5 * (r_01.abs2() + later_sq)
        power = ComplexPair.real(1.0 + 0.0 * first_sq)  # b^{d−1}
        for separation in range(1, beam_count - 1):
            terms[separation] = terms[separation] + 0.5 * (coefficient * power).re
            power = power * bounce
        # separations d ≥ P − 1 together, with the last visibility: Σ_{d≥P−1} C b^{d−1} = C b^{P−2}/(1 − b)
        tail = coefficient * power / (1.0 - bounce)
        terms[beam_count - 1] = terms[beam_count - 1] + 0.5 * tail.re
    return terms


def transmission_terms(terms: Sequence[Any]) -> list[Any]:
    """[T_incoherent, −X_1, …, −X_{P−1}]: the transmittance T(V) = 1 − R(V) of a lossless film on a
    dielectric in the same linear-in-V form as :func:`reflectance_terms` (combine with
    :func:`combine_reflectance_terms`).

    Energy conservation fixes T: for real indices nothing is absorbed, so for every state of coherence the
    reflected and transmitted powers add to the incident one. R(V) is linear in the V_d, hence so is T.
    Checks (tests/optics/test_thin_film.py): under full coherence and P → ∞ it is the Airy transmittance
    (q_s/q_0)|t_01 t_12 e^{iδ/2}/(1 + r_01 r_12 e^{iδ})|², incoherently the sum Σ_p (q_s/q_0)|t_p|² of the
    transmitted beams, both computed from the transmitted amplitudes directly. With P beams the neglected
    ones (≤ the truncation bound of the module docstring) go to T instead of being lost; with
    :func:`film_reflectance_terms` there are none.

    Lossless films only: an absorbing film (κ_f > 0) on a dielectric absorbs A(V) > 0, and its R differs
    between the exterior and the substrate side, which the renderer's film-on-glass sampling relies on
    being equal. :func:`validate_thin_film` rejects that combination rather than return a T that violates
    energy conservation.
    """
    return [1.0 - terms[0], *(-term for term in terms[1:])]


def combine_reflectance_terms(terms: Sequence[Any], visibilities: Sequence[Any]) -> Any:
    """R = R_incoherent + 2 Σ_d V_d X_d with V_d = ``visibilities[d−1]`` (as many as there are X_d)."""
    if len(visibilities) != len(terms) - 1:
        raise InputError(
            f"visibilities: need {len(terms) - 1} values V_1 … V_{{P−1}}, got {len(visibilities)}"
        )
    reflectance = terms[0]
    for term, visibility in zip(terms[1:], visibilities, strict=True):
        reflectance = reflectance + 2.0 * visibility * term
    return reflectance


def bounded_reflectance(terms: Sequence[Any], visibilities: Sequence[Any], ops: ArrayOps) -> Any:
    """:func:`combine_reflectance_terms` clipped to [0, 1]: a reflectance or transmittance (T = 1 − R from
    :func:`transmission_terms`) of :func:`film_reflectance_terms`, whose over-coherent tail can exceed 1 by
    ≤ 2e-3 (module docstring). Clipping R and T alike keeps R + T = 1. Two terms (P = 2) are Eq. (18) as
    published, kept unclipped above so that its fringes are reproduced as the paper has them (on silver its
    maxima exceed 1); they are clipped at 0 only."""
    value = combine_reflectance_terms(terms, visibilities)
    if len(terms) <= 2:
        return ops.maximum(value, 0.0)
    return ops.clip(value, 0.0, 1.0)


def thin_film_reflectance(
    cos_theta_i: Any,
    wavelength_m: Any,
    thickness_m: Any,
    film_ior: Any,
    substrate_eta: ComplexPair,
    exterior_ior: Any,
    visibilities: Sequence[Any],
    ops: ArrayOps,
) -> Any:
    """Unpolarised partially-coherent reflectance of a film on a substrate, P = len(visibilities) + 1 beams.

    Arguments as in :func:`film_amplitudes`; ``visibilities`` = V_1 … V_{P−1}. R ∈ [0, 1].
    """
    amplitudes = film_amplitudes(
        cos_theta_i,
        wavelength_m,
        thickness_m,
        film_ior,
        substrate_eta,
        exterior_ior,
        len(visibilities) + 1,
        ops,
    )
    return combine_reflectance_terms(reflectance_terms(amplitudes), visibilities)


def film_shear(
    normal: Any,
    incident_direction: Any,
    thickness_m: Any,
    film_ior: Any,
    incident_ior: Any,
    ops: ArrayOps,
) -> tuple[Any, Any, Any]:
    """World-space shear s (m) between successive beams of the film: beam p + 1 leaves the top surface at
    Q = P + s, where beam p left (and where the incident ray that beam p + 1 came from entered) at P.

    ``normal`` is the film's unit normal (either side), ``incident_direction`` the unit propagation direction
    of the incident light k̂ (towards the surface), ``film_ior`` n_f and ``incident_ior`` n_0 real, the
    index of the medium k̂ travels in (the exterior, or the substrate for light transmitted up through it). One
    round trip through the film (thickness τ) at the refraction angle θ_t, n_0 sin θ_0 = n_f sin θ_t, moves
    the beam along the surface by 2τ tan θ_t in the plane of incidence, in the direction of k̂'s tangential
    part k̂_t = k̂ − (k̂·n̂)n̂ (|k̂_t| = sin θ_0):

        s = 2τ tan θ_t · k̂_t/|k̂_t| = (2τ n_0 / (n_f cos θ_t)) · k̂_t          (no division by sin θ_0).

    The light reflected at Q along the outgoing direction is the sum of beam 0, incident at Q, and beam 1,
    incident at P = Q − s; they interfere with the incident field's mutual coherence between P and Q, i.e.
    with μ at the projection of s on the plane transverse to k̂ (length 2τ tan θ_t cos θ_0, in the plane of
    incidence; the longitudinal part 2τ tan θ_t sin θ_0 is part of the optical path difference 2 n_f τ cos θ_t
    already in the film phase δ). Beam p + d is sheared by d·s from beam p (``V_d``); the transmitted beams
    of a film on a dielectric enter at the same points, so the same s serves transmission.
    docs/physics_interactions.md §3 compares this with Eq. (18)'s reading τ sin θ_0 (the projection of τn̂).
    Beyond the film's critical angle (n_0 sin θ_0 ≥ n_f) no beam propagates in the film: s = 0 there (the
    later beams' amplitudes vanish with e^{iδ}).

    An absorbing film (η_f = n_f + iκ_f) has no real refraction angle: the wave's planes of constant phase
    and of constant amplitude differ (an inhomogeneous wave). ``film_ior`` is then its real part n_f (a
    ``ComplexPair`` is reduced to it here), i.e. the weak-absorption ray picture, in which the energy
    travels along the phase normal. Its error is second order in κ_f/n_f: the phase fronts in the film
    refract at tan θ_t' = ν/Re q_1, and with q_1² = n_f² − κ_f² − ν² + 2i n_f κ_f,
    Re q_1 = n_f cos θ_t·(1 + ½ κ_f² ν²/(n_f² cos² θ_t)² + O(κ_f⁴)), so tan θ_t overestimates tan θ_t' by the
    relative amount ½ (κ_f/n_f)² tan² θ_t / cos² θ_t: 2 % for κ_f/n_f = 0.3 at θ_t = 30°, < 0.5 % for a
    tarnish-like n_f 2.7, κ_f 0.6 from air (θ_t ≤ 21.7°). The shear only sets the visibilities
    V_d = μ(d·s), which vary
    slowly with |s|.
    """
    if isinstance(film_ior, ComplexPair):
        film_ior = film_ior.re
    along = incident_direction[0] * normal[0] + incident_direction[1] * normal[1]
    along = along + incident_direction[2] * normal[2]
    tangential = tuple(incident_direction[i] - along * normal[i] for i in range(3))
    sin_sq = tangential[0] * tangential[0] + tangential[1] * tangential[1] + tangential[2] * tangential[2]
    ratio = incident_ior / film_ior
    cos_t_sq = 1.0 - ratio * ratio * sin_sq
    propagating = cos_t_sq > 0.0
    scale = ops.where(propagating, 2.0 * thickness_m * ratio / ops.sqrt(ops.maximum(cos_t_sq, 1e-12)), 0.0)
    return (scale * tangential[0], scale * tangential[1], scale * tangential[2])


def validate_thin_film(
    thickness_m: float,
    film_ior: float,
    exterior_ior: float,
    film_extinction: float = 0.0,
    dielectric_substrate: bool = False,
) -> None:
    """Scene-level checks of the film constants (the kernels above cannot raise on Dr.Jit arrays).

    ``film_extinction`` κ_f (dimensionless, ≥ 0) is the film's extinction; an absorbing film is accepted
    on conductor substrates only (:func:`transmission_terms`: T = 1 − R holds for lossless films).
    """
    if not (math.isfinite(film_extinction) and 0.0 <= film_extinction <= MAX_FILM_EXTINCTION):
        raise InputError(
            f"film_extinction: must be a finite extinction in [0, {MAX_FILM_EXTINCTION:g}], "
            f"got {film_extinction}"
        )
    if film_extinction > 0.0 and dielectric_substrate:
        raise InputError(
            "film_extinction: an absorbing film (κ > 0) needs a conductor substrate; on a dielectric its "
            "transmittance is not 1 − R (the film absorbs), which the renderer does not model"
        )
    if not (math.isfinite(thickness_m) and thickness_m >= 0.0):
        raise InputError(f"thickness_m: must be a finite length ≥ 0 m, got {thickness_m}")
    if not (math.isfinite(film_ior) and film_ior >= 1.0):
        raise InputError(f"film_ior: must be a finite real index ≥ 1, got {film_ior}")
    if not (math.isfinite(exterior_ior) and exterior_ior >= 1.0):
        raise InputError(f"exterior_ior: must be a finite real index ≥ 1, got {exterior_ior}")
