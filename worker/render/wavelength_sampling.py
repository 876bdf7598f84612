"""Where a camera sample's four wavelengths go, and what each one is worth (``film.wavelength_sampling``).

Hero set. Each camera sample carries four wavelengths (Mitsuba's spectral variants are four-wide) from one
uniform number u: u_j = frac(u + j/4) and λ_j = P⁻¹(u_j), P the CDF of a density p(λ) (nm⁻¹) on
[λ_min, λ_max]. ``uniform``: p = 1/Λ (Λ = λ_max − λ_min), λ_j = λ_min + Λ·u_j, the stratified hero sampling
of Wilkie et al. 2014. ``importance``: p is tabulated per scene (below) and the rotation happens in P's
primary space, so the four stay stratified in probability (equal spacing in u, warped through P⁻¹).

Estimator weights (derivation). The integrator traces the path x̄ with the hero λ_0's densities and
returns F_j = f_j(x̄)/mean_k p_k(x̄) (docs/integrator.md, "Hero-wavelength MIS per path"). View the four
lanes as four techniques t, technique t producing the pair (λ_t, x̄): λ_t = P⁻¹(u_t) has density p(λ_t)
(u_t is uniform), and given λ_t the hero λ_0 = P⁻¹(frac(P(λ_t) − t/4)) is fixed, so
p_t(λ, x̄) = p(λ)·p(x̄ | R_{−t}(λ)), R_m the rotation by m/4 in primary space. For λ = λ_t the rotations
R_{−s}(λ_t), s = 0…3, run over the whole hero set {λ_k}, hence Σ_s p_s(λ_t, x̄) = p(λ_t)·Σ_k p_k(x̄): the
wavelength density factors out of the balance heuristic w_t = p_t/Σ_s p_s. The multi-sample MIS estimate
of ∫∫ f dλ dx̄ (unbiased whenever Σ_t w_t = 1 and p_t > 0 where w_t f ≠ 0, Veach 1997 §9.2) is

    Σ_t f_t w_t/p_t = Σ_t f_t / Σ_s p_s(λ_t, x̄) = Σ_t F_t / (4 p(λ_t)),

so lane j is worth F_j·ω_j with ω_j = 1/(4 p(λ_j)) nm (``lane_weights``; Λ/4 for uniform sampling), and
band b of width Δ_b is estimated per sample as Σ_j F_j·1_b(λ_j)·ω_j/Δ_b — unbiased for the band-averaged
radiance (1/Δ_b)∫_b L dλ. (Rotating in λ instead of u, λ_j = λ_0 + jΛ/4, would make the four techniques'
wavelength densities differ, p(λ_t − sΛ/4), and give Σ_t f_t/Σ_k p(λ_k); in primary space all four share
p(λ_t), so the balance weights over the set are 1/4 and only the marginal 1/p(λ_j) remains.)
``auto`` (the default) is ``importance`` for emitters with spectral lines and ``uniform`` otherwise
(``sampling_mode``). The renderer multiplies each lane by the dimensionless ratio ρ_λ,j = (1/Λ)/p(λ_j)
(mean 1 under p), which is absent (exactly 1) for uniform sampling, so uniform renders are bitwise those
of before.

Importance density (``importance``). What a pixel's estimate needs is the light there, whose spectrum
follows the emitters' Φ(λ) = Σ_e π A_e c_e s_e(λ) (W·nm⁻¹, the power of each emitter by wavelength), and
the output's weights: the bands (all equal in the spectral EXR) and the colour, which ``images_from_sums``
forms from the bands with the band-integrated CMFs W_b = ∫_b (x̄, ȳ, z̄) dλ. p is piecewise constant on
cells of ≤ 1 nm that tile every band (cell edges fall on band edges):

    p(λ) = m_b · [ f/Δ_b + (1 − f)·Φ(λ)/Φ_b ],   λ in band b,  Φ_b = ∫_b Φ dλ,
    m_b = g/B + (1 − g)·Φ_b v_b / Σ_c Φ_c v_c,   v_b = (W_b,x + W_b,y + W_b,z)/Δ_b,

a defensive mixture twice over: within a band a uniform floor f = ``WITHIN_BAND_FLOOR`` keeps support
between a fluorescent lamp's lines (a reflectance or film may put light there), and the band masses keep a
uniform share g = ``BAND_MASS_FLOOR`` so that no band receives less than half its uniform number of
samples (its variance about doubles at most). Within the band, p ∝ Φ makes F_j/p nearly constant across an
emission line, which is what removes the red/green speckle: with uniform sampling a 25 nm band's estimate
depends on whether a sample hit a 5 nm line. A simulation of the band → XYZ → CIELAB pipeline (16 bands,
380–780 nm, white and green diffuse patches, 16 spp) gave chroma-variance reductions of 11–22× under F11,
2.0–3.7× under F7, 4–8× under F2, and 0.85–1.6× under D65, with the worst band's relative error at most
1.5× uniform's (D65); putting more of the band masses on Φ_b·v_b (g = 0.2) gained more under F11 but made a
white patch under D65 1.5× noisier in chroma and the worst band 2.4×. Without emitters (Σ Φ_c v_c = 0)
the masses are uniform; a band without emission is sampled uniformly within.

Kernels sample p through its quantile table: G = ``QUANTILE_INTERVALS`` knots λ_i = P⁻¹(i/G); the density
actually sampled, and used for the weights, is the piecewise-constant 1/(G·(λ_{i+1} − λ_i)), which follows
p to within the cells' resolution (the estimator is unbiased for whichever density it samples, as long
as it uses that density). A lane counts in the band its λ falls in, under both modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from hgcore.artifacts.layout import BandLayout
from hgcore.colour import band_edges_xyz_weights
from hgcore.errors import InputError
from schemas.photometry import emitter_area_m2, emitter_radiance_scale, evaluate_spectrum
from schemas.scene import D65Spectrum, EnvironmentEmitter, SunEmitter

WITHIN_BAND_FLOOR = 0.2  # f: the uniform share of the density inside a band
BAND_MASS_FLOOR = 0.5  # g: the uniform share of the band masses
MAX_CELL_NM = 1.0  # cells tile each band with at most this width (the emitter spectra's own spacing)
SUBSAMPLES_PER_CELL = 8  # Φ is averaged over each cell at this many points
#: ``auto`` samples by importance when the emitters' line spikiness κ (``line_spikiness``) exceeds this: a
#: smooth spectrum (D65 1.004, blackbody ≈ 1.00) keeps the uniform kernels, a lamp with lines (F-series
#: 1.07–1.37) does not — importance sampling gains little on smooth spectra and costs the bands where the
#: CMFs vanish up to ~1.5× relative error (measured: Cornell D65, the worst band 0.025 → 0.036 at 64 spp).
SPIKY_THRESHOLD = 1.02
SPIKY_WINDOW_NM = 20.0
SPIKY_POINTS_PER_WINDOW = 200
#: G: the kernels sample the equal-probability intervals [P⁻¹(i/G), P⁻¹((i+1)/G)] (O(1): two gathers per
#: lane; a binary search over the cells cost ~20 % of a thin-film sample). Where p is lowest (the floors,
#: ≥ 0.1/Λ) an interval is ≤ 10Λ/G ≈ 1 nm wide for Λ = 400 nm.
QUANTILE_INTERVALS = 4096


def emitted_spectral_power(scene: Any, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Φ(λ) = Σ_e π·A_e·c_e·s_e(λ) in W·nm⁻¹ at ``wavelengths_nm``: each emitter's Lambertian radiance
    c·s(λ) (``schemas.photometry``) times π and its emitting area. Emitters at infinity count the irradiance
    they give one square metre facing them: a sun Ω·c·s(λ), an environment π·c·s(λ) (an image's colours
    are upsampled with D65: its spectral shape is taken as D65's)."""
    film = scene.film
    power = np.zeros(np.shape(wavelengths_nm))
    for emitter in scene.emitters:
        scale = emitter_radiance_scale(emitter, film.wavelength_min_nm, film.wavelength_max_nm)
        if isinstance(emitter, EnvironmentEmitter):
            spectrum_model = emitter.spectrum if emitter.spectrum is not None else D65Spectrum(type="d65")
            power += math.pi * scale * evaluate_spectrum(spectrum_model, wavelengths_nm)
            continue
        spectrum = evaluate_spectrum(emitter.spectrum, wavelengths_nm)
        if isinstance(emitter, SunEmitter):
            power += emitter.solid_angle_sr() * scale * spectrum
            continue
        power += math.pi * emitter_area_m2(emitter) * scale * spectrum
    return power


@dataclass(frozen=True)
class CellDensity:
    """A piecewise-constant wavelength density: ``probabilities[i]`` (sum 1) on the i-th of
    ``cells_per_band`` × B equal cells tiling [λ_min, λ_max] (band b's cells are b·k … b·k + k − 1)."""

    bands: BandLayout
    cells_per_band: int
    probabilities: np.ndarray

    @property
    def cell_nm(self) -> float:
        return self.bands.width_nm / self.cells_per_band


def importance_density(bands: BandLayout, spectral_power: Any) -> CellDensity:
    """The ``importance`` density of the module docstring for a film's ``bands``, from a callable
    ``spectral_power(wavelengths_nm) -> Φ`` (W·nm⁻¹)."""
    cells_per_band = max(1, math.ceil(bands.width_nm / MAX_CELL_NM - 1e-9))
    cell_count = cells_per_band * bands.band_count
    cell_nm = bands.width_nm / cells_per_band
    offsets = (np.arange(SUBSAMPLES_PER_CELL) + 0.5) / SUBSAMPLES_PER_CELL
    points = bands.wavelength_min_nm + cell_nm * (np.arange(cell_count)[:, None] + offsets)
    # Cell integrals ∫_cell Φ dλ (midpoint rule), grouped by band.
    cell_power = np.asarray(spectral_power(points), dtype=float).mean(axis=1) * cell_nm
    if np.any(~np.isfinite(cell_power)) or np.any(cell_power < 0.0):
        raise InputError("wavelength_sampling: emitter spectra must be finite and non-negative")
    cell_power = cell_power.reshape(bands.band_count, cells_per_band)
    band_power = cell_power.sum(axis=1)
    # Within band b: f/k + (1 − f)·Φ_cell/Φ_b (uniform where the band has no emission).
    safe_power = np.where(band_power > 0.0, band_power, 1.0)[:, None]
    shape = np.where(
        band_power[:, None] > 0.0,
        WITHIN_BAND_FLOOR / cells_per_band + (1.0 - WITHIN_BAND_FLOOR) * cell_power / safe_power,
        1.0 / cells_per_band,
    )
    visibility = band_edges_xyz_weights(bands.edges_nm).sum(axis=1) / bands.width_nm
    weighted = band_power * visibility
    masses = np.full(bands.band_count, 1.0 / bands.band_count)
    if weighted.sum() > 0.0:
        masses = BAND_MASS_FLOOR * masses + (1.0 - BAND_MASS_FLOOR) * weighted / weighted.sum()
    probabilities = (masses[:, None] * shape).ravel()
    return CellDensity(bands, cells_per_band, probabilities / probabilities.sum())


def line_spikiness(spectral_power: Any, wavelength_min_nm: float, wavelength_max_nm: float) -> float:
    """κ = Σ_w (Φ_w/Σ Φ)·⟨Φ²⟩_w/⟨Φ⟩_w² over windows w of ≈ ``SPIKY_WINDOW_NM`` tiling the range: the factor
    by which emission lines inflate a window's uniform-sampling variance (1 for a flat spectrum; D65 1.004,
    F7 1.07, F11 1.37 over 380–780 nm). 1 without emission."""
    windows = max(1, round((wavelength_max_nm - wavelength_min_nm) / SPIKY_WINDOW_NM))
    edges = np.linspace(wavelength_min_nm, wavelength_max_nm, windows + 1)
    offsets = (np.arange(SPIKY_POINTS_PER_WINDOW) + 0.5) / SPIKY_POINTS_PER_WINDOW
    points = edges[:-1, None] + np.diff(edges)[:, None] * offsets
    power = np.asarray(spectral_power(points), dtype=float)
    mean = power.mean(axis=1)
    if mean.sum() <= 0.0:
        return 1.0
    safe = np.where(mean > 0.0, mean, 1.0)
    return float(np.sum(mean / mean.sum() * np.where(mean > 0.0, (power**2).mean(axis=1) / safe**2, 1.0)))


def sampling_mode(scene: Any) -> str:
    """``uniform`` or ``importance``: the film's choice, ``auto`` resolved by ``line_spikiness`` of the
    emitters' spectral power against ``SPIKY_THRESHOLD``."""
    mode = scene.film.wavelength_sampling
    if mode != "auto":
        return mode
    film = scene.film
    spikiness = line_spikiness(
        lambda wavelengths: emitted_spectral_power(scene, wavelengths),
        film.wavelength_min_nm,
        film.wavelength_max_nm,
    )
    return "importance" if spikiness > SPIKY_THRESHOLD else "uniform"


def scene_density(scene: Any, bands: BandLayout) -> CellDensity | None:
    """The density of ``sampling_mode(scene)`` on the film's ``bands``: None for ``uniform``."""
    if sampling_mode(scene) == "uniform":
        return None
    return importance_density(bands, lambda wavelengths: emitted_spectral_power(scene, wavelengths))


def lane_weights(span_nm: float, lane_count: int, ratios: list[Any] | None) -> list[Any]:
    """ω_j = 1/(lane_count·p(λ_j)) nm per lane: (Λ/lane_count)·ρ_λ,j, or the plain number Λ/lane_count
    under uniform sampling (``ratios`` None), so that uniform kernels stay as they were."""
    if ratios is None:
        return [span_nm / lane_count] * lane_count
    return [ratio * (span_nm / lane_count) for ratio in ratios]


class WavelengthSample(NamedTuple):
    """A camera sample's wavelengths (nm), each lane's ratio ρ_λ,j = (1/Λ)/p(λ_j) (None: uniform, all 1)
    and the band each lane counts in."""

    wavelengths: Any  # mi.Spectrum
    ratios: list[Any] | None  # mi.Float per lane
    band_of_lane: list[Any]  # mi.UInt32 per lane


def quantile_knots(density: CellDensity, interval_count: int = QUANTILE_INTERVALS) -> np.ndarray:
    """λ_i = P⁻¹(i/G), i = 0…G (nm, float32): the knots of the density the kernels sample exactly."""
    bands = density.bands
    cdf = np.concatenate([[0.0], np.cumsum(density.probabilities)])
    cdf /= cdf[-1]
    edges = bands.wavelength_min_nm + density.cell_nm * np.arange(density.probabilities.size + 1)
    # P is piecewise linear (p piecewise constant, > 0 everywhere): invert it by linear interpolation.
    knots = np.interp(np.arange(interval_count + 1) / interval_count, cdf, edges)
    knots[0], knots[-1] = bands.wavelength_min_nm, bands.wavelength_max_nm
    knots = knots.astype(np.float32)
    if np.any(np.diff(knots) <= 0.0):
        raise InputError("wavelength_sampling: the density is too peaked for its quantile table")
    return knots


def knot_pdf_nm(knots: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """The density the kernels sample, 1/(G·(λ_{i+1} − λ_i)) on [λ_i, λ_{i+1}) (nm⁻¹; for tests)."""
    lengths = np.diff(knots.astype(np.float64))
    index = np.clip(np.searchsorted(knots, wavelengths_nm, side="right") - 1, 0, lengths.size - 1)
    return 1.0 / (lengths.size * lengths[index])


class WavelengthSampler:
    """Draws hero sets from one uniform number per sample (module docstring), in Dr.Jit."""

    def __init__(self, mi: Any, bands: BandLayout, density: CellDensity | None) -> None:
        self.mi = mi
        self.bands = bands
        self.density = density
        self.knots = None if density is None else quantile_knots(density)
        self._knots = None if self.knots is None else mi.Float(self.knots)

    def kernel_tables(self) -> list[Any]:
        """The arrays ``sample`` reads: the quantile table (none for uniform sampling)."""
        return [] if self._knots is None else [self._knots]

    def sample(self, u: Any) -> WavelengthSample:
        """The hero set of ``u`` (mi.Float in [0, 1)): u_j = frac(u + j/4) mapped through P⁻¹."""
        import drjit as dr

        mi = self.mi
        bands = self.bands
        span = bands.wavelength_max_nm - bands.wavelength_min_nm
        wavelengths = mi.Spectrum(0.0)
        lane_count = len(wavelengths)
        ratios = None if self._knots is None else []
        band_of_lane = []
        for j in range(lane_count):
            fraction = u + j / lane_count
            fraction = fraction - dr.floor(fraction)
            if self._knots is None:
                wavelengths[j] = bands.wavelength_min_nm + span * fraction
            else:
                # Interval i of the quantile table, position t in it: λ = λ_i + t·(λ_{i+1} − λ_i), of
                # density 1/(G·(λ_{i+1} − λ_i)), so ρ = (1/Λ)/p = G·(λ_{i+1} − λ_i)/Λ.
                count = self.knots.size - 1
                scaled = fraction * count
                index = dr.minimum(mi.UInt32(scaled), count - 1)
                lower = dr.gather(mi.Float, self._knots, index)
                length = dr.gather(mi.Float, self._knots, index + 1) - lower
                wavelengths[j] = lower + (scaled - mi.Float(index)) * length
                ratios.append(length * (count / span))
            band = (wavelengths[j] - bands.wavelength_min_nm) / bands.width_nm
            band_of_lane.append(mi.UInt32(dr.clip(band, 0, bands.band_count - 1)))
        return WavelengthSample(wavelengths, ratios, band_of_lane)
