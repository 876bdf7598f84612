"""Noise-aware comparison of a render with its baseline: per-band relative RMSE, ΔE₀₀, coherence drift.

Both renders are Monte Carlo estimates, so each pixel p of band b is a mean with variance v_p (from
``variance.exr``). A metric fails only if its effect size exceeds the threshold AND a significance test says
the difference is not noise (|z| > z_crit, default 5, i.e. a false-failure rate < 1e-6 per test for
Gaussian statistics):

* Bands. Image-mean test: d_b = mean_p(c − a), Var[d_b] = Σ_p (v_a + v_c) / N² (pixels independent), so
  z_b = d_b / √Var[d_b]. Per-pixel excess test: E[(c − a)²] = δ² + v_a + v_c, so the excess
  e_p = (c − a)² − v_a − v_c estimates the squared true difference δ²; under no change its sum has
  variance ≈ Σ_p 2 (v_a + v_c)² (Gaussian pixel means), giving z_excess = Σ e_p / √(Σ 2 (v_a + v_c)²).
  Effect size: the noise-corrected relative RMSE √max(0, mean_p e_p) / rms_p(a); the raw relative RMSE
  √mean_p (c − a)² / rms_p(a) is reported too. A band fails if its corrected RMSE > ``max_rel_rmse`` and
  max(|z_b|, z_excess) > z_crit.
* Colour. Band spectra → CIE 1931 XYZ → CIELAB with the D65 white scaled to the baseline's 99th-percentile
  luminance (one white for both images); per-pixel ΔE₀₀ mean, p95, max. p95 fails if > ``max_delta_e00_p95``
  and some band differs significantly (colour cannot change unless the spectrum does).
* Coherence. Over pixels with weight > 0 in both, the median relative change (c − a)/a of ℓ₁, ℓ₂ and
  anisotropy; significance by the sign test: under no change P(c > a) = ½ exactly (the two renders are
  exchangeable), so z = (n₊ − n₋)/√(n₊ + n₋). Fails if |median| > ``max_coherence_drift`` and |z| > z_crit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hgrender.colour import D65_WHITE_XYZ, bands_to_xyz, ciede2000, xyz_to_lab
from service.regression.images import COHERENCE_METRIC_CHANNELS, RenderOutputs
from service.regression.models import Thresholds

WHITE_PERCENTILE = 99.0
"""Luminance percentile of the baseline that is the CIELAB reference white (robust against fireflies)."""


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


def band_metrics(baseline: RenderOutputs, current: RenderOutputs) -> list[dict[str, float]]:
    """Per band: means, z of the mean difference, excess z, raw and noise-corrected relative RMSE."""
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
        results.append(
            {
                "wavelength_nm": float(center_nm),
                "mean_baseline": float(np.mean(a[..., band])),
                "mean_current": float(np.mean(c[..., band])),
                "z_mean": float(_z_score(float(np.mean(diff)), float(np.sum(var)) / pixel_count**2)),
                "z_excess": float(_z_score(float(np.sum(excess)), float(np.sum(2.0 * var**2)))),
                "rel_rmse": float(np.sqrt(np.mean(diff**2)) / rms),
                "rel_rmse_corrected": float(np.sqrt(max(0.0, float(np.mean(excess)))) / rms),
            }
        )
    return results


def delta_e00_metrics(baseline: RenderOutputs, current: RenderOutputs) -> dict[str, float]:
    """Per-pixel ΔE₀₀ statistics of the two spectral images (one reference white, from the baseline)."""
    xyz_a = bands_to_xyz(baseline.bands, baseline.band_centers_nm)
    xyz_c = bands_to_xyz(current.bands, current.band_centers_nm)
    white_y = float(np.percentile(xyz_a[..., 1], WHITE_PERCENTILE))
    white_xyz = D65_WHITE_XYZ * (white_y if white_y > 0.0 else 1.0)
    delta_e = ciede2000(xyz_to_lab(xyz_a, white_xyz), xyz_to_lab(xyz_c, white_xyz))
    return {
        "mean": float(np.mean(delta_e)),
        "p95": float(np.percentile(delta_e, 95.0)),
        "max": float(np.max(delta_e)),
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
    colour = delta_e00_metrics(baseline, current)
    coherence = coherence_metrics(baseline, current)
    reasons = []
    significant_bands = [b for b in bands if max(abs(b["z_mean"]), b["z_excess"]) > z_crit]
    for band in significant_bands:
        if band["rel_rmse_corrected"] > thresholds.max_rel_rmse:
            reasons.append(
                f"{scene}: rel_rmse of band {band['wavelength_nm']:.1f} nm is "
                f"{band['rel_rmse_corrected']:.4f} > {thresholds.max_rel_rmse} (z_mean "
                f"{band['z_mean']:.1f}, z_excess {band['z_excess']:.1f})"
            )
    if significant_bands and colour["p95"] > thresholds.max_delta_e00_p95:
        reasons.append(
            f"{scene}: delta_e00_p95 is {colour['p95']:.3f} > {thresholds.max_delta_e00_p95} "
            f"({len(significant_bands)} bands differ significantly)"
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
        "z_max": max(max(abs(b["z_mean"]), b["z_excess"]) for b in bands),
        "delta_e00": colour,
        "coherence": coherence,
    }
    return Comparison(scene, metrics, reasons)
