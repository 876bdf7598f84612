"""Noise-aware comparison of a render with its baseline: per-band relative RMSE, ΔE₀₀, ꟻLIP, coherence drift.

Both renders are Monte Carlo estimates, so each pixel p of band b is a mean with variance v_p (from
``variance.exr``). A metric fails only if its effect size exceeds the threshold AND a significance test says
the difference is not noise (|z| > z_crit, default 5, i.e. a false-failure rate < 1e-6 per test for
Gaussian statistics):

* Bands. Image-mean test: d_b = mean_p(c − a), Var[d_b] = Σ_p (v_a + v_c) / N² (pixels independent), so
  z_b = d_b / √Var[d_b]. Per-pixel excess test: E[(c − a)²] = δ² + v_a + v_c, so the excess
  e_p = (c − a)² − v_a − v_c estimates the squared true difference δ²; under no change E[e_p] = 0 and
  z_excess = Σ e_p / √(Σ e_p²) is a self-normalised sum (asymptotically N(0, 1) for independent pixels
  whatever their distribution: pixel means of a few samples are far from Gaussian, so a Gaussian
  variance of (c − a)² would understate the tails). Per-pixel test: t_p = (c − a)/√(v_a + v_c) is
  antisymmetric under exchanging the two renders, so under no change it is symmetric about 0 whatever
  the pixel's distribution, and z_pixel = Σ t_p / √(Σ t_p²) (self-normalised) weights each pixel by its
  own noise: a few noisy pixels (an emitter's edges) cannot hide a change of every quiet pixel, which
  they do in z_b's unweighted image mean.
  Effect sizes: the relative change of the band's image mean, d_b / mean_p(a), and the noise-corrected
  relative RMSE √max(0, mean_p e_p) / rms_p(a) (the raw √mean_p (c − a)² / rms_p(a) is reported too). A
  band fails if |relative mean change| > ``max_rel_mean_change`` or its corrected RMSE > ``max_rel_rmse``,
  and its significance max(|z_b|, |z_pixel|, z_excess) > z_crit.
* Colour. Both images at one exposure, the EV that maps the baseline's 99th-percentile luminance to white
  (``exposure_ev``, stored with the metrics; the compare view opens at it): per-pixel CIEDE2000 ΔE₀₀ of
  band spectra → CIE 1931 XYZ → CIELAB, and per-pixel ꟻLIP of the displayed images
  (``hgcore.image_metrics``, the same code as the compare view): mean, p95, max. Noise alone gives large
  values at few spp, so their level is estimated by a parametric bootstrap: the metric between a and
  a + ε √(v_a + v_c) (ε ~ N(0, 1) per pixel and band, clipped at 0, four draws, fixed seed) gives
  ``p95_noise``/``mean_noise``; ΔE₀₀'s p95 − p95_noise fails if > ``max_delta_e00_p95`` and ꟻLIP's
  mean − mean_noise if > ``max_flip_mean``, each only when some band differs significantly (colour
  cannot change unless the spectrum does).
* Coherence. Over pixels with weight > 0 in both, the median relative change (c − a)/a of ℓ₁, ℓ₂ and
  anisotropy; significance by the sign test: under no change P(c > a) = ½ exactly (the two renders are
  exchangeable), so z = (n₊ − n₋)/√(n₊ + n₋). Fails if |median| > ``max_coherence_drift`` and |z| > z_crit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hgcore.image_metrics import map_statistics, metric_exposure_ev, perceptual_map
from hgcore.regression.images import COHERENCE_METRIC_CHANNELS, RenderOutputs
from hgcore.regression.models import Thresholds

NOISE_DRAWS = 4
"""Bootstrap draws of the ΔE₀₀ and ꟻLIP noise levels (4 × the pixel count samples their 95th percentile)."""


@dataclass
class Comparison:
    """Metrics of one scene versus its baseline, the verdict and the reasons for a failure."""

    scene: str
    metrics: dict[str, Any]
    reasons: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        return "fail" if self.reasons else "pass"


def _z_score(difference: float, variance: float) -> float:
    if variance > 0.0:
        return difference / np.sqrt(variance)
    return 0.0 if difference == 0.0 else float(np.copysign(np.inf, difference))


def band_significance(band: dict[str, float]) -> float:
    """The band's largest test statistic: max(|z_mean|, |z_pixel|, z_excess)."""
    return max(abs(band["z_mean"]), abs(band["z_pixel"]), band["z_excess"])


def band_metrics(baseline: RenderOutputs, current: RenderOutputs) -> list[dict[str, float]]:
    """Per band: means, the z of the mean difference, per-pixel and excess z, raw and noise-corrected
    relative RMSE."""
    a, c = baseline.bands, current.bands
    variance = baseline.band_variance + current.band_variance
    pixel_count = a.shape[0] * a.shape[1]
    rms_all = float(np.sqrt(np.mean(a**2)))
    results = []
    for band, center_nm in enumerate(baseline.band_centers_nm):
        diff = c[..., band] - a[..., band]
        var = variance[..., band]
        rms = float(np.sqrt(np.mean(a[..., band] ** 2))) or rms_all or 1.0
        excess = diff**2 - var
        noisy = var > 0.0
        t = diff[noisy] / np.sqrt(var[noisy])
        mean_baseline = float(np.mean(a[..., band]))
        results.append(
            {
                "wavelength_nm": float(center_nm),
                "mean_baseline": mean_baseline,
                "mean_current": float(np.mean(c[..., band])),
                "rel_mean_change": float(_z_score(float(np.mean(diff)), mean_baseline**2)),
                "z_mean": float(_z_score(float(np.mean(diff)), float(np.sum(var)) / pixel_count**2)),
                "z_pixel": float(_z_score(float(np.sum(t)), float(np.sum(t**2)))),
                "z_excess": float(_z_score(float(np.sum(excess)), float(np.sum(excess**2)))),
                "rel_rmse": float(np.sqrt(np.mean(diff**2)) / rms),
                "rel_rmse_corrected": float(np.sqrt(max(0.0, float(np.mean(excess)))) / rms),
            }
        )
    return results


def perceptual_metrics(
    metric: str, baseline: RenderOutputs, current: RenderOutputs, exposure_ev: float
) -> dict[str, float]:
    """Per-pixel ``de2000`` (ΔE₀₀) or ``flip`` (ꟻLIP) statistics of the two spectral images at
    ``exposure_ev`` (``hgcore.image_metrics``, the compare view's code), with the noise level.

    Noise alone gives large values at few spp, so the level is estimated by a parametric bootstrap: the
    metric between a and a + ε √(v_a + v_c) (ε ~ N(0, 1) per pixel and band, clipped at 0, four draws,
    fixed seed) gives ``mean_noise`` and ``p95_noise``; the excesses are what noise does not explain."""
    centers_nm = baseline.band_centers_nm
    values = perceptual_map(metric, baseline.bands, current.bands, centers_nm, exposure_ev)
    rng = np.random.default_rng(0)
    sigma = np.sqrt(baseline.band_variance + current.band_variance)
    noise = np.concatenate(
        [
            perceptual_map(
                metric,
                baseline.bands,
                np.maximum(baseline.bands + sigma * rng.standard_normal(sigma.shape), 0.0),
                centers_nm,
                exposure_ev,
            ).ravel()
            for _ in range(NOISE_DRAWS)
        ]
    )
    stats = map_statistics(values)
    noise_stats = map_statistics(noise)
    return {
        **stats,
        "exposure_ev": exposure_ev,
        "mean_noise": noise_stats["mean"],
        "p95_noise": noise_stats["p95"],
        "mean_excess": max(0.0, stats["mean"] - noise_stats["mean"]),
        "p95_excess": max(0.0, stats["p95"] - noise_stats["p95"]),
    }


def coherence_metrics(baseline: RenderOutputs, current: RenderOutputs) -> dict[str, dict[str, float]]:
    """Median relative change and sign-test z of ℓ₁, ℓ₂, anisotropy over pixels covered in both."""
    results: dict[str, dict[str, float]] = {}
    if "weight" not in baseline.coherence or "weight" not in current.coherence:
        return results
    covered = (baseline.coherence["weight"] > 0) & (current.coherence["weight"] > 0)
    for name in COHERENCE_METRIC_CHANNELS:
        if name not in baseline.coherence or name not in current.coherence:
            continue
        a, c = baseline.coherence[name][covered], current.coherence[name][covered]
        usable = np.isfinite(a) & np.isfinite(c) & (a > 0)
        a, c = a[usable], c[usable]
        if a.size == 0:
            continue
        n_up, n_down = int(np.sum(c > a)), int(np.sum(c < a))
        results[name] = {
            "median_rel_change": float(np.median((c - a) / a)),
            "z_sign": float(_z_score(n_up - n_down, n_up + n_down)),
            "pixels": int(a.size),
        }
    return results


def compare_renders(
    scene: str, baseline: RenderOutputs, current: RenderOutputs, thresholds: Thresholds
) -> Comparison:
    """All metrics of ``current`` versus ``baseline`` and the verdict under ``thresholds``."""
    if baseline.bands.shape != current.bands.shape or not np.allclose(
        baseline.band_centers_nm, current.band_centers_nm
    ):
        return Comparison(
            scene,
            {},
            [
                f"{scene}: image layout changed (baseline {baseline.bands.shape}, current "
                f"{current.bands.shape}); promote a new baseline"
            ],
        )
    z_crit = thresholds.z_critical
    bands = band_metrics(baseline, current)
    exposure_ev = metric_exposure_ev(baseline.bands, baseline.band_centers_nm)
    colour = perceptual_metrics("de2000", baseline, current, exposure_ev)
    flip = perceptual_metrics("flip", baseline, current, exposure_ev)
    coherence = coherence_metrics(baseline, current)
    reasons = []
    significant_bands = [b for b in bands if band_significance(b) > z_crit]
    for band in significant_bands:
        if abs(band["rel_mean_change"]) > thresholds.max_rel_mean_change:
            reasons.append(
                f"{scene}: rel_mean_change of band {band['wavelength_nm']:.1f} nm is "
                f"{band['rel_mean_change']:+.4f} (|.| > {thresholds.max_rel_mean_change}, "
                f"z {band_significance(band):.1f})"
            )
        if band["rel_rmse_corrected"] > thresholds.max_rel_rmse:
            reasons.append(
                f"{scene}: rel_rmse of band {band['wavelength_nm']:.1f} nm is "
                f"{band['rel_rmse_corrected']:.4f} > {thresholds.max_rel_rmse} "
                f"(z {band_significance(band):.1f})"
            )
    if significant_bands and colour["p95_excess"] > thresholds.max_delta_e00_p95:
        reasons.append(
            f"{scene}: delta_e00_p95 is {colour['p95']:.3f}, {colour['p95_excess']:.3f} above its noise "
            f"level > {thresholds.max_delta_e00_p95} ({len(significant_bands)} bands differ significantly)"
        )
    if significant_bands and flip["mean_excess"] > thresholds.max_flip_mean:
        reasons.append(
            f"{scene}: flip_mean is {flip['mean']:.4f}, {flip['mean_excess']:.4f} above its noise level "
            f"> {thresholds.max_flip_mean} ({len(significant_bands)} bands differ significantly)"
        )
    for name, drift in coherence.items():
        if abs(drift["median_rel_change"]) > thresholds.max_coherence_drift and abs(drift["z_sign"]) > z_crit:
            reasons.append(
                f"{scene}: coherence_drift of {name} is {drift['median_rel_change']:+.4f} (|.| > "
                f"{thresholds.max_coherence_drift}, sign-test z {drift['z_sign']:.1f})"
            )
    metrics = {
        "bands": bands,
        "rel_rmse_max": max(b["rel_rmse_corrected"] for b in bands),
        "z_max": max(band_significance(b) for b in bands),
        "exposure_ev": exposure_ev,
        "delta_e00": colour,
        "flip": flip,
        "coherence": coherence,
    }
    return Comparison(scene, metrics, reasons)
