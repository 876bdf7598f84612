"""Scatter by a rough statistical surface: Eq. (15) read as the Harvey–Shack / Rayleigh–Rice BRDF.

Eq. (15): the scattered intensity is the incident intensity times S_surf(φ⊥), the PSD of the *normalised*
surface autocorrelation at the lobe's spatial frequency φ⊥ = k(ω_o⊥ + ω_i⊥) (local shading frame, z = normal,
ω_i towards the light, ω_o towards the viewer, β = (x, y) direction cosines). In cycles per metre,
f = φ⊥/2π = n_i(β_o + β_i)/λ with λ the vacuum wavelength (m) and n_i the exterior index; S is in m² and
∫ S d²f = 1.

Harvey partition (Harvey 2012; Krywonos 2006): a fraction e^{−g} of the Fresnel-reflected power stays in the
specular (delta) lobe, g = (4π σ_h n_i cos θ_i / λ)² (σ_h the RMS height, m), and the rest is scattered.
Generalised Harvey–Shack renormalisation (Krywonos 2006, §4): the scattered power F(1 − e^{−g}) is shared
among the *propagating* frequencies only — the part of the PSD beyond the horizon (|β_o| ≥ 1) is
evanescent, carries no power, and must not take any away — so the lobe is divided by the propagating
fraction P(θ_i, λ) = ∫_{|β_o|<1} S d²f (``propagating_fraction``):

    f_r(ω_i, ω_o) = F(θ_i) (1 − e^{−g}) S(f) (n_i/λ)² / P(θ_i, λ)      [1/sr].

Since dω_o = d²β_o / cos θ_o and d²f = (n_i/λ)² d²β_o, ∫ f_r cos θ_o dω_o = F (1 − e^{−g}) exactly: with the
specular part the directional albedo is F(θ_i), never more (issue 12; without the 1/P factor a σ 0.3 µm,
ℓ_c 1 µm glass read 0.874 in a furnace). Harvey–Shack's F, g and P belong to the incident side, so the
model is not reciprocal; the renderer evaluates it with the side its paths arrive from as ω_i
(``worker.render.bsdfs``), which makes its albedo exactly F(θ) and the sample weights constant.

The lobe is importance-sampled *exactly*: draw f from S (Gaussian PSD: Box–Muller; ABC PSD: closed-form
inverse of the radial CDF), map β_o = λf/n_i − β_i and reject |β_o| ≥ 1. The solid-angle density is
p(ω_o) = S(f)(n_i/λ)² cos θ_o, so the sample weight f_r cos θ_o / p is the constant F (1 − e^{−g}). The paper
(§5.2) sampled a hand-tuned microfacet proxy instead; exact sampling has zero weight variance within the lobe.

Transmission through a rough dielectric interface (n_i → n_t) uses the same PSD with the phase-matching
condition n_t β_t = λ f − n_i β_i (β_t the direction cosines of the transmitted direction, which points into
the lower half-space), the Fresnel transmittance T = 1 − R and the transmission roughness exponent
g_t = (2π σ_h (n_i cos θ_i − n_t cos θ_t)/λ)² of the specular refraction angle θ_t:
f_t = T (1 − e^{−g_t}) S(f) (n_t/λ)² [1/sr], p(ω_t) = S(f)(n_t/λ)² |cos θ_t|, weight T (1 − e^{−g_t}).

PSD models of the normalised autocorrelation (σ_h carried separately by g):
  Gaussian, R(r) = exp(−r²/ℓ_c²):     S(f) = π ℓ_c² exp(−(π ℓ_c |f|)²).
  ABC / K-correlation, exponent C > 1: S(f) = A / (1 + (B|f|)²)^{(C+1)/2},  A = B²(C − 1)/(2π),
      with B = 2π ℓ_c: the FT pair of R(r) ∝ (r/ℓ_c)^ν K_ν(r/ℓ_c), ν = (C − 1)/2 (Church & Takacs 1991),
      so ℓ_c is the K-correlation length; radial CDF P(|f| < F) = 1 − (1 + B²F²)^{−(C−1)/2}.
Directions are 3-sequences (a tuple of arrays or a Mitsuba ``Vector3f``); formulas run on NumPy and Dr.Jit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.array_ops import ArrayOps

PsdModel = Literal["gaussian", "abc"]


@dataclass(frozen=True)
class RoughSurface:
    """Surface statistics: RMS height σ_h (m), correlation length ℓ_c (m), PSD model and ABC exponent C."""

    rms_height_m: float
    correlation_length_m: float
    psd_model: PsdModel = "gaussian"
    abc_exponent: float = 2.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rms_height_m) and self.rms_height_m >= 0.0):
            raise InputError(f"rms_height_m: must be a finite length ≥ 0 m, got {self.rms_height_m}")
        if not (math.isfinite(self.correlation_length_m) and self.correlation_length_m > 0.0):
            raise InputError(
                f"correlation_length_m: must be a finite length > 0 m, got {self.correlation_length_m}"
            )
        if self.psd_model not in ("gaussian", "abc"):
            raise InputError(f"psd_model: must be 'gaussian' or 'abc', got {self.psd_model!r}")
        if not (math.isfinite(self.abc_exponent) and self.abc_exponent > 1.0):
            raise InputError(
                f"abc_exponent: must be finite and > 1 (normalisable PSD), got {self.abc_exponent}"
            )

    @property
    def abc_b_m(self) -> float:
        """B = 2π ℓ_c of the ABC model (m)."""
        return 2.0 * math.pi * self.correlation_length_m

    def local(self, rms_height_m: Any, correlation_length_m: Any) -> RoughSurface:
        """The same PSD model with per-point σ_h and ℓ_c (arrays: a textured surface, one value per lane).
        Not validated: the caller's values are already within the model's ranges (textures are clipped to
        them when the scene is compiled)."""
        surface = object.__new__(RoughSurface)
        for name, value in (
            ("rms_height_m", rms_height_m),
            ("correlation_length_m", correlation_length_m),
            ("psd_model", self.psd_model),
            ("abc_exponent", self.abc_exponent),
        ):
            object.__setattr__(surface, name, value)
        return surface


def surface_psd(surface: RoughSurface, frequency_sq_per_m2: Any, ops: ArrayOps) -> Any:
    """S(f) in m² at |f|² (cycles²/m²) of the normalised autocorrelation (∫ S d²f = 1)."""
    length_m = surface.correlation_length_m
    if surface.psd_model == "gaussian":
        return math.pi * length_m**2 * ops.exp(-((math.pi * length_m) ** 2) * frequency_sq_per_m2)
    exponent = surface.abc_exponent
    b_m = surface.abc_b_m
    amplitude_m2 = b_m**2 * (exponent - 1.0) / (2.0 * math.pi)
    return amplitude_m2 * ops.exp(-0.5 * (exponent + 1.0) * ops.log(1.0 + b_m**2 * frequency_sq_per_m2))


def sample_psd_frequency(surface: RoughSurface, u1: Any, u2: Any, ops: ArrayOps) -> tuple[Any, Any]:
    """Draw f = (f_x, f_y) (cycles/m) with density S(f) from uniforms ``u1, u2`` in [0, 1)."""
    one_minus_u1 = 1.0 - u1  # in (0, 1]: keeps the logarithms finite
    if surface.psd_model == "gaussian":
        # S is a normal density with per-axis std 1/(√2 π ℓ_c); Box–Muller radius.
        sigma_per_m = 1.0 / (math.sqrt(2.0) * math.pi * surface.correlation_length_m)
        radius_per_m = sigma_per_m * ops.sqrt(-2.0 * ops.log(one_minus_u1))
    else:
        # Invert 1 − (1 + B²F²)^{−(C−1)/2} = u1.
        growth = ops.exp((-2.0 / (surface.abc_exponent - 1.0)) * ops.log(one_minus_u1))
        radius_per_m = ops.sqrt(ops.maximum(growth - 1.0, 0.0)) / surface.abc_b_m
    angle = 2.0 * math.pi * u2
    return radius_per_m * ops.cos(angle), radius_per_m * ops.sin(angle)


def radial_cdf(surface: RoughSurface, radius_per_m: Any, ops: ArrayOps) -> Any:
    """P(|f| < F) of the PSD read as a density over the frequency plane (F ≥ 0, cycles/m)."""
    if surface.psd_model == "gaussian":
        return 1.0 - ops.exp(-((math.pi * surface.correlation_length_m) ** 2) * radius_per_m * radius_per_m)
    growth = 1.0 + surface.abc_b_m**2 * radius_per_m * radius_per_m
    return 1.0 - ops.exp((-0.5 * (surface.abc_exponent - 1.0)) * ops.log(growth))


# Gauss–Legendre nodes/weights on [0, 1] for the angular integral of ``propagating_fraction``.
_LEGENDRE_NODES, _LEGENDRE_WEIGHTS = np.polynomial.legendre.leggauss(32)
_ANGLE_FRACTIONS = [float(0.5 * (node + 1.0)) for node in _LEGENDRE_NODES]
_ANGLE_WEIGHTS = [float(0.5 * weight) for weight in _LEGENDRE_WEIGHTS]


def propagating_fraction(
    surface: RoughSurface,
    sin_theta_i: Any,
    wavelength_m: Any,
    ops: ArrayOps,
    exterior_ior: Any = 1.0,
    exit_ior: Any = 1.0,
    reflection: bool = False,
) -> Any:
    """P = ∫ S d²f over the frequencies that propagate after scattering (dimensionless, in [0, 1]).

    ``reflection``: n_o = n_i, so the disk always contains 0 (t₋ < 0) and the cheaper one-sided form with
    constant angles is used (a quarter of the work: this runs per wavelength at every rough vertex).

    In the frequency plane the propagating set is the disk |f − c| < ρ, c = n_i β_i/λ (|c| = n_i sin θ_i/λ),
    ρ = n_o/λ (n_o = n_i for reflection, n_t for transmission: |β_o| < 1). S is rotationally symmetric about
    0, so along each direction e at angle φ from c the disk covers t ∈ [t₋, t₊], t± = c·e ± √(ρ² − |c|² +
    (c·e)²), and P = (1/π) ∫ [CDF(max(t₊, 0)) − CDF(max(t₋, 0))] dφ with the closed-form radial CDF
    (``radial_cdf``), over φ ∈ [0, π] when the disk contains 0 and over the directions that meet it,
    φ ∈ [0, φ_m], sin φ_m = ρ/|c|, when it does not (transmission into a rarer medium beyond the critical
    angle); there φ = φ_m(1 − s²) removes the √(φ_m − φ) end point. 32 Gauss–Legendre nodes: error
    ≤ 2e-3 for θ_i ≤ 82° (tests: against a direct 2-D quadrature over the disk), up to 6e-3 within 3° of
    grazing, where a narrow lobe's cut by the horizon is sharp.
    """
    centre = exterior_ior * sin_theta_i / wavelength_m
    radius = exit_ior / wavelength_m
    if reflection:
        total_reflection: Any = 0.0
        for fraction, weight in zip(_ANGLE_FRACTIONS, _ANGLE_WEIGHTS, strict=True):
            along = centre * math.cos(math.pi * fraction)
            root = ops.sqrt(ops.maximum(radius * radius - centre * centre + along * along, 0.0))
            total_reflection = total_reflection + weight * radial_cdf(surface, along + root, ops)
        return total_reflection
    outside = centre > radius
    gap = ops.sqrt(ops.maximum(centre * centre - radius * radius, 0.0))
    angle_max = ops.where(outside, ops.atan2(radius, gap), math.pi)
    total: Any = 0.0
    for fraction, weight in zip(_ANGLE_FRACTIONS, _ANGLE_WEIGHTS, strict=True):
        angle = ops.where(outside, angle_max * (1.0 - fraction * fraction), math.pi * fraction)
        jacobian = ops.where(outside, 2.0 * angle_max * fraction / math.pi, 1.0)
        along = centre * ops.cos(angle)
        discriminant = radius * radius - centre * centre + along * along
        root = ops.sqrt(ops.maximum(discriminant, 0.0))
        upper = radial_cdf(surface, ops.maximum(along + root, 0.0), ops)
        lower = radial_cdf(surface, ops.maximum(along - root, 0.0), ops)
        total = total + weight * jacobian * ops.where(discriminant > 0.0, upper - lower, 0.0)
    return total


# Grid of ``reflection_fraction_table``: sin θ = 1 − (1 − x)² (dense near grazing, where P changes fastest)
# on 65 nodes of x, and vacuum wavelengths on 36 nodes over 300–1000 nm.
TABLE_ANGLE_NODES = 65
TABLE_WAVELENGTHS_M = np.linspace(300e-9, 1000e-9, 36)


def reflection_fraction_table(surface: RoughSurface) -> np.ndarray:
    """P of reflection in air (n_i = n_o = 1) on the (x, λ) grid, shape (angles, wavelengths), for kernels
    that interpolate it bilinearly instead of integrating per sample (tests bound the interpolation
    error against :func:`propagating_fraction`)."""
    from hgcore.optics.array_ops import NUMPY

    x = np.linspace(0.0, 1.0, TABLE_ANGLE_NODES)
    sin_theta = 1.0 - (1.0 - x) ** 2
    grid_sin, grid_wavelength = np.meshgrid(sin_theta, TABLE_WAVELENGTHS_M, indexing="ij")
    return np.asarray(propagating_fraction(surface, grid_sin, grid_wavelength, NUMPY, reflection=True))


#: Spacing of ``reflection_fraction_ratio_table``'s nodes in ln(ℓ_c/λ): about that of the wavelength
#: nodes above (their ln λ steps are 0.020–0.067).
RATIO_TABLE_LOG_STEP = 0.03
MAX_RATIO_NODES = 1024


def ratio_table_nodes(ratio_min: float, ratio_max: float) -> np.ndarray:
    """The ℓ_c/λ nodes of ``reflection_fraction_ratio_table`` for ratios in [min, max]: log-uniform,
    ≈ ``RATIO_TABLE_LOG_STEP`` apart (at least 2, at most ``MAX_RATIO_NODES``)."""
    low, high = math.log(ratio_min), math.log(max(ratio_max, ratio_min * 1.0001))
    count = min(MAX_RATIO_NODES, max(2, math.ceil((high - low) / RATIO_TABLE_LOG_STEP) + 1))
    return np.exp(np.linspace(low, high, count))


def reflection_fraction_ratio_table(surface: RoughSurface, ratios: np.ndarray) -> np.ndarray:
    """P of reflection in air on the (x, ℓ_c/λ) grid, shape (angles, ratios), for a surface whose ℓ_c
    varies (a texture). P depends on ℓ_c and λ only through their ratio: scaling the frequency plane by λ
    maps the propagating disk to centre sin θ, radius 1 and the PSD's argument ℓ_c·f to (ℓ_c/λ)·f'; so the
    ratio ρ is evaluated as a surface of ℓ_c = 1 m at λ = 1/ρ m."""
    from hgcore.optics.array_ops import NUMPY

    unit = RoughSurface(surface.rms_height_m, 1.0, surface.psd_model, surface.abc_exponent)
    x = np.linspace(0.0, 1.0, TABLE_ANGLE_NODES)
    sin_theta = 1.0 - (1.0 - x) ** 2
    grid_sin, grid_ratio = np.meshgrid(sin_theta, np.asarray(ratios, dtype=float), indexing="ij")
    return np.asarray(propagating_fraction(unit, grid_sin, 1.0 / grid_ratio, NUMPY, reflection=True))


def roughness_exponent(
    rms_height_m: float, cos_theta_i: Any, wavelength_m: Any, exterior_ior: float = 1.0
) -> Any:
    """Harvey's g = (4π σ_h n_i cos θ_i / λ)²; e^{−g} is the specular fraction of reflection."""
    phase = 4.0 * math.pi * rms_height_m * exterior_ior * cos_theta_i / wavelength_m
    return phase * phase


def transmission_roughness_exponent(
    rms_height_m: float,
    cos_theta_i: Any,
    cos_theta_t: Any,
    wavelength_m: Any,
    exterior_ior: float,
    interior_ior: float,
) -> Any:
    """g_t = (2π σ_h (n_i cos θ_i − n_t |cos θ_t|)/λ)² of the specularly refracted direction."""
    phase = 2.0 * math.pi * rms_height_m * (exterior_ior * cos_theta_i - interior_ior * cos_theta_t)
    phase = phase / wavelength_m
    return phase * phase


def hemisphere_direction(
    beta_x: Any, beta_y: Any, valid: Any, ops: ArrayOps, lower: bool = False
) -> tuple[Any, Any, Any]:
    """Unit direction with direction cosines β (z ≥ 0, or ≤ 0 if ``lower``); the normal where not ``valid``.

    Invalid samples (|β| ≥ 1, or non-finite β from an extreme PSD draw) get ±ẑ so that no NaN direction
    reaches the ray tracer; their pdf and weight are 0.
    """
    beta_sq = beta_x * beta_x + beta_y * beta_y
    z = ops.sqrt(ops.maximum(1.0 - beta_sq, 0.0))
    sign = -1.0 if lower else 1.0
    return (
        ops.where(valid, beta_x, 0.0),
        ops.where(valid, beta_y, 0.0),
        ops.where(valid, sign * z, sign),
    )


def _lobe_density_beta(
    surface: RoughSurface,
    wi: Any,
    wo: Any,
    wavelength_m: Any,
    exterior_ior: float,
    exit_ior: float,
    ops: ArrayOps,
) -> Any:
    """Density of β_o per unit d²β_o: S(f)(n_o/λ)² at f = (n_o β_o + n_i β_i)/λ."""
    scale_per_m = 1.0 / wavelength_m
    fx = (exit_ior * wo[0] + exterior_ior * wi[0]) * scale_per_m
    fy = (exit_ior * wo[1] + exterior_ior * wi[1]) * scale_per_m
    return surface_psd(surface, fx * fx + fy * fy, ops) * (exit_ior * scale_per_m) ** 2


def rough_reflection_eval(
    surface: RoughSurface,
    wi: Any,
    wo: Any,
    wavelength_m: Any,
    reflectance: Any,
    ops: ArrayOps,
    exterior_ior: float = 1.0,
    fraction: Any = None,
) -> Any:
    """Scattered BRDF f_r [1/sr] (without cos θ_o), renormalised over the propagating frequencies;
    ``reflectance`` is F(θ_i). 0 below the horizon. ``fraction``: P if the caller has it (a kernel's lookup
    table of :func:`propagating_fraction`), else it is computed."""
    g = roughness_exponent(surface.rms_height_m, wi[2], wavelength_m, exterior_ior)
    density = _lobe_density_beta(surface, wi, wo, wavelength_m, exterior_ior, exterior_ior, ops)
    if fraction is None:
        sin_i = ops.sqrt(ops.maximum(wi[0] * wi[0] + wi[1] * wi[1], 0.0))
        fraction = propagating_fraction(
            surface, sin_i, wavelength_m, ops, exterior_ior, exterior_ior, reflection=True
        )
    value = reflectance * (1.0 - ops.exp(-g)) * density / ops.maximum(fraction, 1e-12)
    return ops.where((wi[2] > 0.0) & (wo[2] > 0.0), value, 0.0)


def rough_reflection_pdf(
    surface: RoughSurface, wi: Any, wo: Any, wavelength_m: Any, ops: ArrayOps, exterior_ior: float = 1.0
) -> Any:
    """Solid-angle density of :func:`rough_reflection_sample`: S(f)(n_i/λ)² cos θ_o."""
    density = _lobe_density_beta(surface, wi, wo, wavelength_m, exterior_ior, exterior_ior, ops)
    return ops.where((wi[2] > 0.0) & (wo[2] > 0.0), density * wo[2], 0.0)


def rough_reflection_sample(
    surface: RoughSurface,
    wi: Any,
    wavelength_m: Any,
    u1: Any,
    u2: Any,
    ops: ArrayOps,
    exterior_ior: float = 1.0,
) -> tuple[tuple[Any, Any, Any], Any, Any]:
    """Sample the scattered lobe: ``((wo_x, wo_y, wo_z), pdf_solid_angle, valid)``.

    Invalid where the drawn frequency maps outside the unit disk (evanescent) or ω_i is below the horizon;
    the weight f_r cos θ_o / pdf of a valid sample is F (1 − e^{−g}).
    """
    fx, fy = sample_psd_frequency(surface, u1, u2, ops)
    wavelength_in_medium_m = wavelength_m / exterior_ior
    beta_x = wavelength_in_medium_m * fx - wi[0]
    beta_y = wavelength_in_medium_m * fy - wi[1]
    beta_sq = beta_x * beta_x + beta_y * beta_y
    valid = (beta_sq < 1.0) & (wi[2] > 0.0)
    wo = hemisphere_direction(beta_x, beta_y, valid, ops)
    pdf = ops.where(valid, rough_reflection_pdf(surface, wi, wo, wavelength_m, ops, exterior_ior), 0.0)
    return wo, pdf, valid


def rough_transmission_eval(
    surface: RoughSurface,
    wi: Any,
    wt: Any,
    wavelength_m: Any,
    transmittance: Any,
    cos_theta_t_specular: Any,
    ops: ArrayOps,
    exterior_ior: float,
    interior_ior: float,
) -> Any:
    """Scattered BTDF f_t [1/sr] (without |cos θ_t|) into the lower half-space (wt[2] < 0), renormalised over
    the propagating frequencies (|β_t| < 1), in the transmitted medium's solid angle (no n² factor).

    ``transmittance`` is T(θ_i) = 1 − R and ``cos_theta_t_specular`` the specular refraction cosine, both from
    :func:`hgcore.optics.fresnel.fresnel_dielectric` with η = n_t/n_i.
    """
    g_t = transmission_roughness_exponent(
        surface.rms_height_m, wi[2], cos_theta_t_specular, wavelength_m, exterior_ior, interior_ior
    )
    density = _lobe_density_beta(surface, wi, wt, wavelength_m, exterior_ior, interior_ior, ops)
    sin_i = ops.sqrt(ops.maximum(wi[0] * wi[0] + wi[1] * wi[1], 0.0))
    fraction = propagating_fraction(surface, sin_i, wavelength_m, ops, exterior_ior, interior_ior)
    value = transmittance * (1.0 - ops.exp(-g_t)) * density / ops.maximum(fraction, 1e-12)
    return ops.where((wi[2] > 0.0) & (wt[2] < 0.0), value, 0.0)


def rough_transmission_pdf(
    surface: RoughSurface,
    wi: Any,
    wt: Any,
    wavelength_m: Any,
    ops: ArrayOps,
    exterior_ior: float,
    interior_ior: float,
) -> Any:
    """Solid-angle density of :func:`rough_transmission_sample`: S(f)(n_t/λ)² |cos θ_t|."""
    density = _lobe_density_beta(surface, wi, wt, wavelength_m, exterior_ior, interior_ior, ops)
    return ops.where((wi[2] > 0.0) & (wt[2] < 0.0), density * (-wt[2]), 0.0)


def rough_transmission_sample(
    surface: RoughSurface,
    wi: Any,
    wavelength_m: Any,
    u1: Any,
    u2: Any,
    ops: ArrayOps,
    exterior_ior: float,
    interior_ior: float,
) -> tuple[tuple[Any, Any, Any], Any, Any]:
    """Sample the transmitted lobe: ``((wt_x, wt_y, wt_z), pdf_solid_angle, valid)`` with wt_z < 0.

    The weight f_t |cos θ_t| / pdf of a valid sample is T (1 − e^{−g_t}).
    """
    fx, fy = sample_psd_frequency(surface, u1, u2, ops)
    beta_x = (wavelength_m * fx - exterior_ior * wi[0]) / interior_ior
    beta_y = (wavelength_m * fy - exterior_ior * wi[1]) / interior_ior
    beta_sq = beta_x * beta_x + beta_y * beta_y
    valid = (beta_sq < 1.0) & (wi[2] > 0.0)
    wt = hemisphere_direction(beta_x, beta_y, valid, ops, lower=True)
    pdf = ops.where(
        valid, rough_transmission_pdf(surface, wi, wt, wavelength_m, ops, exterior_ior, interior_ior), 0.0
    )
    return wt, pdf, valid
