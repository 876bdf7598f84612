"""What a receiver passes on to the detector: the source's angular distribution times an acceptance.

The light a pixel collects from an incoherent source through an interaction is an incoherent sum of plane
waves, one per source direction ω that the interaction sends towards the pixel. A thin film evaluates each
plane wave coherently at its own incidence, so the pixel sees the film's interference term averaged over
those directions (docs/physics_interactions.md §3, "What a pixel sees"):

    ⟨e^{iδ(ω)}⟩ = ∫ f_s(ω) a(ω) e^{iδ(ω)} dω / ∫ f_s(ω) a(ω) dω,

f_s the source's angular distribution (its transverse intensity seen from the receiver: mean m_s,
covariance C_s = Σ⊥/r², rad²) and a(ω) the *acceptance*: the weight with which the interaction passes
direction ω on towards the pixel for the outgoing direction the path fixed. With δ linear in ω about a
direction m, δ(ω) ≈ δ(m) + g·(ω − m), and a Gaussian f_s·a of mean m and covariance C,

    ⟨e^{iδ}⟩ = e^{iδ(m)} · exp(−½ gᵀCg)                                     (0th HG mode)

— the film's visibility with Σ⊥_eff = r²C, at the phase of direction m (``hgcore.optics.coherence``). Limits:
an acceptance of one direction (C_a → 0: a specular interaction passes one direction of the source) gives
the path's own direction and full visibility; one that covers the source (C_a → ∞: a receiver beyond a
diffuse vertex) the whole source at its centre, the paper's Eq. 18.

Acceptance of a rough lobe (Eq. 15), for the outgoing direction the path fixed: the lobe read as a density of
incident directions, centred on the mirror direction, restricted to the propagating ones as the renderer
renormalises it (``lobe_acceptance_variance``); in the receiver's transverse frame a step ε along the plane
of incidence moves β by ε cos θ, so C_a = v (I + n⊥n⊥ᵀ/n_z²), n = (n⊥, n_z) the surface normal in that frame
(``lobe_covariance_components``).

The product (``flat_top_product_components``). Every emitter is a *uniform* silhouette, for which the
Gaussian product of the covariances (``product_components``: C = (C_s⁻¹ + C_a⁻¹)⁻¹ = K C_s,
m = m_a + K(m_s − m_a), K = C_a(C_a + C_s)⁻¹) pulls the mean towards the source's centre (a flat source does
not) and halves the variance at equal widths (the restricted lobe keeps ≈ 2/3 of it); the flat-top product
takes the moments of the acceptance restricted to the source instead. Errors against an exact quadrature,
and why the camera's lens cone is not combined here but averaged by the paths (``worker.render.thin_lens``):
docs/physics_interactions.md §3, "What a pixel sees".
"""

from __future__ import annotations

import math
from typing import Any

from hgcore.optics.array_ops import ArrayOps
from hgcore.optics.rough_surface import RoughSurface

#: The longest wavelength a scene renders (the schema's limit), at which a lobe is widest.
NARROW_LOBE_WAVELENGTH_M = 2.5e-6


def lobe_acceptance_variance(
    surface: RoughSurface, exterior_ior: float, wavelength_m: Any, ops: ArrayOps
) -> Any:
    """The per-axis variance (rad²) of the incident direction cosines β that a rough lobe (Eq. 15) passes
    towards one outgoing direction: the lobe's density in β, S(n(β − β_c)/λ), over the propagating disk
    |β − β_c| < 1 about its centre β_c (the renderer renormalises the lobe over the propagating directions,
    so every PSD has a finite one; about the centre rather than the true horizon |β| < 1: exact at normal
    incidence, and the truncation only matters for lobes of width ≳ 0.3). Radially, with r = |β − β_c|:

    * Gaussian PSD: β has per-axis std s = λ/(√2 π ℓ_c n) (``rough_surface.sample_psd_frequency``), and
      with u = 1/(2s²), ⟨r²⟩/2 = s² [1 − e^{−u}(1 + u)]/(1 − e^{−u}) (→ s² for narrow lobes);
    * ABC (K-correlation), exponent C: density ∝ (1 + r²/b²)^{−q}, b = λ/(2π ℓ_c n), q = (C + 1)/2, and with
      U = 1 + 1/b², ⟨r²⟩ = b² I₃/I₁, I₁ = (1 − U^{1−q})/(q − 1), I₃ = (U^{2−q} − 1)/(2 − q) − I₁ (ln U − I₁
      at q = 2): finite although the untruncated lobe has no second moment for C ≤ 3. Its heavy tail makes
      it several times its core b: for C = 1.2, b = 0.175 (ℓ_c 0.5 µm at 550 nm) the std is 0.34.
    """
    n = exterior_ior
    if surface.psd_model == "gaussian":
        std = wavelength_m / (math.sqrt(2.0) * math.pi * surface.correlation_length_m * n)
        variance = std * std
        if NARROW_LOBE_WAVELENGTH_M / (math.sqrt(2.0) * math.pi * surface.correlation_length_m * n) <= 0.12:
            return variance  # e^{−u} < e^{−34} at every wavelength: the truncation changes nothing
        u = 0.5 / ops.maximum(variance, 1e-30)
        tail = ops.exp(-ops.minimum(u, 80.0))
        return ops.minimum(variance * (1.0 - tail * (1.0 + u)) / ops.maximum(1.0 - tail, 1e-30), 0.25)
    scale = wavelength_m / (2.0 * math.pi * surface.correlation_length_m * n)  # b
    scale2 = scale * scale
    log_u = ops.log(1.0 + 1.0 / ops.maximum(scale2, 1e-30))
    q = 0.5 * (surface.abc_exponent + 1.0)
    first = (1.0 - ops.exp((1.0 - q) * log_u)) / (q - 1.0)
    # ∫ u^{1−q} du from 1 to U: ln U at q = 2 (an ABC exponent of 3)
    rising = log_u if abs(q - 2.0) < 1e-6 else (ops.exp((2.0 - q) * log_u) - 1.0) / (2.0 - q)
    third = rising - first
    return ops.minimum(0.5 * scale2 * third / ops.maximum(first, 1e-30), 0.25)


def lobe_covariance_components(
    variance_rad2: Any, normal: tuple[Any, Any, Any], ops: ArrayOps
) -> tuple[Any, Any, Any]:
    """(C_xx, C_xy, C_yy), rad²: a rough lobe's acceptance in a transverse frame (x, y, k) of the incident
    light, from the per-axis variance of β (``variance_rad2`` = v λ²) and the surface normal's components
    ``normal`` = (n·x, n·y, n·k): C = v λ² (I + n⊥n⊥ᵀ/n_z²) — the inverse of the foreshortening
    I − n⊥n⊥ᵀ (Sherman–Morrison: |n⊥|² + n_z² = 1)."""
    stretch = variance_rad2 / ops.maximum(normal[2] * normal[2], 1e-12)
    return (
        variance_rad2 + stretch * normal[0] * normal[0],
        stretch * normal[0] * normal[1],
        variance_rad2 + stretch * normal[1] * normal[1],
    )


#: The offset scale of the flat-top product (``flat_top_product_components``) for a uniform ellipse
#: (spheres, disks, scattering regions) and a uniform parallelogram (rectangles; cylinders, whose
#: silhouette is a strip).
ELLIPSE_OFFSET_SCALE = math.sqrt(3.0) / 2.0
PARALLELOGRAM_OFFSET_SCALE = 1.0


#: Abramowitz & Stegun 26.2.17: P(Z > x) = φ(x)·Σ_k b_k t^k, t = 1/(1 + p x), for x ≥ 0 (|error| < 7.5e-8).
NORMAL_TAIL_P = 0.2316419
NORMAL_TAIL_B = (0.319381530, -0.356563782, 1.781477937, -1.821255978, 1.330274429)


def _normal_cdf(x: Any, density: Any, ops: ArrayOps) -> Any:
    """Φ(x) from the standard normal density φ(x) at x (A&S 26.2.17: the tail shares φ's exponential, and
    P(Z > |x|) keeps its relative precision far in the tails, where 1 − erf would round to 0)."""
    t = 1.0 / (1.0 + NORMAL_TAIL_P * ops.abs(x))
    polynomial = NORMAL_TAIL_B[-1]
    for coefficient in NORMAL_TAIL_B[-2::-1]:
        polynomial = polynomial * t + coefficient
    tail = density * polynomial * t
    return ops.where(x >= 0.0, 1.0 - tail, tail)


def _truncated_normal_moments(half_width: Any, mean: Any, std: Any, ops: ArrayOps) -> tuple[Any, Any, Any]:
    """(mean, variance, mass) of N(mean, std²) restricted to [−half_width, half_width] (1-D, exact):
    with a = (−w − μ)/s, b = (w − μ)/s and Z = Φ(b) − Φ(a), the mean is μ + s(φ(a) − φ(b))/Z and the
    variance s²[1 + (aφ(a) − bφ(b))/Z − ((φ(a) − φ(b))/Z)²]."""
    safe_std = ops.maximum(std, 1e-30)
    a = (-half_width - mean) / safe_std
    b = (half_width - mean) / safe_std
    density_a = ops.exp(-0.5 * ops.minimum(a * a, 1e4)) / math.sqrt(2.0 * math.pi)
    density_b = ops.exp(-0.5 * ops.minimum(b * b, 1e4)) / math.sqrt(2.0 * math.pi)
    mass = _normal_cdf(b, density_b, ops) - _normal_cdf(a, density_a, ops)
    # Far outside the interval (mass → 0, lost to rounding) the moments are meaningless but must stay finite:
    # the caller clamps them into the interval. With this floor |shift| ≤ 4e11 and the squares stay finite.
    safe_mass = ops.maximum(mass, 1e-12)
    shift = (density_a - density_b) / safe_mass
    # a·φ(a) with a clipped: φ vanishes long before a overflows
    spread = (ops.clip(a, -1e2, 1e2) * density_a - ops.clip(b, -1e2, 1e2) * density_b) / safe_mass
    variance = safe_std * safe_std * ops.maximum(1.0 + spread - shift * shift, 0.0)
    return mean + safe_std * shift, variance, mass


def flat_top_axes(
    source_cov: tuple[Any, Any, Any], acceptance_cov: tuple[Any, Any, Any], ops: ArrayOps
) -> tuple[tuple[Any, Any], tuple[Any, Any]]:
    """The axes of ``flat_top_product_components``: the principal axes of C_s·tr C_a + C_a·tr C_s (the
    acceptance's for an isotropic source, the source's for an isotropic acceptance). A scale of C_a leaves
    them unchanged, so a lobe's axes serve every wavelength."""
    sxx, sxy, syy = source_cov
    axx, axy, ayy = acceptance_cov
    trace_a, trace_s = axx + ayy, sxx + syy
    bxx, bxy, byy = (
        sxx * trace_a + axx * trace_s,
        sxy * trace_a + axy * trace_s,
        syy * trace_a + ayy * trace_s,
    )
    root = ops.sqrt((bxx - byy) * (bxx - byy) + 4.0 * bxy * bxy)
    isotropic = root <= 1e-6 * ops.maximum(bxx + byy, 1e-30)
    cos_2phi = ops.where(isotropic, 1.0, (bxx - byy) / ops.maximum(root, 1e-30))
    sin_2phi = ops.where(isotropic, 0.0, 2.0 * bxy / ops.maximum(root, 1e-30))
    cos_phi = ops.sqrt(ops.maximum(0.5 * (1.0 + cos_2phi), 0.0))
    sin_phi = ops.sqrt(ops.maximum(0.5 * (1.0 - cos_2phi), 0.0))
    sin_phi = ops.where(sin_2phi < 0.0, -sin_phi, sin_phi)
    return (cos_phi, sin_phi), (-sin_phi, cos_phi)


def flat_top_product_components(
    source_mean: tuple[Any, Any],
    source_cov: tuple[Any, Any, Any],
    acceptance_mean: tuple[Any, Any],
    acceptance_cov: tuple[Any, Any, Any],
    unbounded: Any,
    offset_scale: Any,
    ops: ArrayOps,
    axes: tuple[tuple[Any, Any], tuple[Any, Any]] | None = None,
) -> tuple[tuple[Any, Any], tuple[Any, Any, Any]]:
    """(m, C) of a *uniform* source (covariance C_s, rad²) times a Gaussian acceptance: the mean and
    covariance of the acceptance restricted to the source (module docstring, "The product").

    Per axis e_i (``flat_top_axes``, or ``axes`` computed once for acceptances of one shape) the source is
    the box of equal variance, ±√3σ_i, and the acceptance the normal of variance e_iᵀC_a e_i; their
    product's moments are the truncated normal's (``_truncated_normal_moments``). ``offset_scale``:
    ``ELLIPSE_OFFSET_SCALE`` for a uniform ellipse — its edge lies at 2σ_i, the box's at √3σ_i, so offsets
    from the centre are scaled by √3/2 before and back after (an acceptance near the ellipse's edge is
    truncated there) — or ``PARALLELOGRAM_OFFSET_SCALE``. Limits: C_a → 0 gives (m_a, 0) inside the
    source (clamped into it); C_a → ∞ (or ``unbounded``) the source's own (m_s, C_s); C_s = 0 (a point
    source) gives (m_s, 0). An acceptance far outside the source (a faint lane) has its truncated moments
    clamped into the source's box: its mean to the edge, its variance to the box's."""
    sxx, sxy, syy = source_cov
    axx, axy, ayy = acceptance_cov
    axes = flat_top_axes(source_cov, acceptance_cov, ops) if axes is None else axes
    offset = (acceptance_mean[0] - source_mean[0], acceptance_mean[1] - source_mean[1])
    means, variances = [], []
    for ex, ey in axes:
        source_var = ops.maximum(ex * ex * sxx + 2.0 * ex * ey * sxy + ey * ey * syy, 0.0)
        acceptance_var = ops.maximum(ex * ex * axx + 2.0 * ex * ey * axy + ey * ey * ayy, 0.0)
        half_width = math.sqrt(3.0) * ops.sqrt(source_var)
        along = (ex * offset[0] + ey * offset[1]) * offset_scale
        mean, variance, _ = _truncated_normal_moments(half_width, along, ops.sqrt(acceptance_var), ops)
        # A point-like acceptance (the truncation's width 0) sits where it is.
        point = acceptance_var <= 1e-12 * ops.maximum(source_var, 1e-30)
        mean = ops.minimum(ops.maximum(ops.where(point, along, mean), -half_width), half_width)
        variance = ops.where(point, 0.0, ops.minimum(variance, source_var))
        means.append(mean / offset_scale)
        variances.append(variance)
    (e1x, e1y), (e2x, e2y) = axes
    mean = (
        source_mean[0] + means[0] * e1x + means[1] * e2x,
        source_mean[1] + means[0] * e1y + means[1] * e2y,
    )
    cov = (
        variances[0] * e1x * e1x + variances[1] * e2x * e2x,
        variances[0] * e1x * e1y + variances[1] * e2x * e2y,
        variances[0] * e1y * e1y + variances[1] * e2y * e2y,
    )
    if unbounded is True:
        return source_mean, source_cov
    if unbounded is not False:
        mean = tuple(ops.where(unbounded, s, m) for s, m in zip(source_mean, mean, strict=True))
        cov = tuple(ops.where(unbounded, s, c) for s, c in zip(source_cov, cov, strict=True))
    return mean, cov


def product_components(
    source_mean: tuple[Any, Any],
    source_cov: tuple[Any, Any, Any],
    acceptance_mean: tuple[Any, Any],
    acceptance_cov: tuple[Any, Any, Any],
    unbounded: Any,
    ops: ArrayOps,
) -> tuple[tuple[Any, Any], tuple[Any, Any, Any]]:
    """(m, C) of the normalised product of two Gaussians in a transverse plane (means in rad, covariances
    (xx, xy, yy) in rad²): K = C_a (C_a + C_s)⁻¹, m = m_a + K(m_s − m_a), C = K C_s (symmetrised).

    ``unbounded`` (bool or array): the acceptance covers every direction (K = I: the source itself). Where
    C_a + C_s is singular (a point source seen through a Dirac interaction: both zero) K = 0 and m = m_a.
    Both limits are exact in floating point: C_a = 0 gives K = 0, C_s = 0 with C_a > 0 gives K = I.
    """
    axx, axy, ayy = acceptance_cov
    sxx, sxy, syy = source_cov
    txx, txy, tyy = axx + sxx, axy + sxy, ayy + syy
    det = txx * tyy - txy * txy
    inverse_det = ops.where(det > 0.0, 1.0 / ops.maximum(det, 1e-30), 0.0)
    # K = A T⁻¹, T⁻¹ = [[tyy, −txy], [−txy, txx]] / det
    k11 = (axx * tyy - axy * txy) * inverse_det
    k12 = (axy * txx - axx * txy) * inverse_det
    k21 = (axy * tyy - ayy * txy) * inverse_det
    k22 = (ayy * txx - axy * txy) * inverse_det
    if unbounded is True:
        k11, k12, k21, k22 = 1.0, 0.0, 0.0, 1.0
    elif unbounded is not False:
        k11 = ops.where(unbounded, 1.0, k11)
        k12 = ops.where(unbounded, 0.0, k12)
        k21 = ops.where(unbounded, 0.0, k21)
        k22 = ops.where(unbounded, 1.0, k22)
    dx = source_mean[0] - acceptance_mean[0]
    dy = source_mean[1] - acceptance_mean[1]
    mean = (acceptance_mean[0] + k11 * dx + k12 * dy, acceptance_mean[1] + k21 * dx + k22 * dy)
    cov = (
        k11 * sxx + k12 * sxy,
        0.5 * (k11 * sxy + k12 * syy + k21 * sxx + k22 * sxy),
        k21 * sxy + k22 * syy,
    )
    return mean, cov
