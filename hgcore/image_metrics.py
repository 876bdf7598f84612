"""Per-pixel perceptual differences of two spectral images, at one exposure: CIEDE2000 ΔE₀₀ and ꟻLIP.

The one implementation behind the regression run's colour metrics (``hgcore.regression.metrics``), the
viewer's compare view and the regression dashboard (``GET /v1/compare``, ``service.viewer_data``), so that
a ΔE₀₀ p95 stored by a run is the number the compare view shows for the same two jobs.

Exposure. Both images are scaled by 2^EV before the comparison; EV is chosen on the *reference* image by
:func:`metric_exposure_ev` (its 99th-percentile luminance Y becomes 1, the display white, as the viewer's
automatic exposure does) unless the caller gives one: a run stores the EV it used (``exposure_ev``), the
dashboard opens the compare view at it.

* ΔE₀₀: band radiances → CIE 1931 XYZ (band-integrated CMFs, ``hgcore.colour.radiance_xyz``, over
  ∫ȳ dλ: the scale of the EXR's linear sRGB) × 2^EV →
  CIELAB with the D65 white at Y = 1 → CIEDE2000 per pixel. Not tone-mapped and not clipped: values above
  white keep their (large) lightness differences.
* ꟻLIP (Andersson et al. 2020, ``flip-evaluator``): LDR-ꟻLIP of the two images as the viewer shows them
  at that exposure with the clamp tone map (XYZ → linear sRGB × 2^EV, clipped to [0, 1], sRGB-encoded),
  at the package's default 67 pixels per degree. Per-pixel error in [0, 1].
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from hgcore.colour import D65_WHITE_XYZ, XYZ_TO_LINEAR_SRGB, ciede2000, radiance_xyz, xyz_to_lab
from hgcore.errors import InputError
from hgcore.imaging import srgb_encode

EXPOSURE_PERCENTILE = 99.0
"""Luminance percentile of the reference that the exposure maps to white (robust against fireflies)."""
PerceptualMetric = Literal["de2000", "flip"]
PERCEPTUAL_METRICS: tuple[str, ...] = ("de2000", "flip")


def metric_exposure_ev(bands: np.ndarray, band_centers_nm: np.ndarray) -> float:
    """EV (stops) that maps the reference's 99th-percentile luminance Y to 1; 0 for a black image."""
    luminance = radiance_xyz(bands, band_centers_nm)[..., 1]
    high = float(np.percentile(luminance, EXPOSURE_PERCENTILE))
    return -math.log2(high) if high > 0.0 and math.isfinite(high) else 0.0


def _exposed_xyz(bands: np.ndarray, band_centers_nm: np.ndarray, exposure_ev: float) -> np.ndarray:
    if not math.isfinite(exposure_ev):
        raise InputError(f"ev: must be finite, got {exposure_ev}")
    return radiance_xyz(bands, band_centers_nm) * 2.0**exposure_ev


def delta_e00_map(
    reference: np.ndarray, sample: np.ndarray, band_centers_nm: np.ndarray, exposure_ev: float
) -> np.ndarray:
    """Per-pixel CIEDE2000 of two (H, W, B) band images exposed by 2^EV (white: D65 at Y = 1)."""
    lab = [
        xyz_to_lab(_exposed_xyz(bands, band_centers_nm, exposure_ev), D65_WHITE_XYZ)
        for bands in (reference, sample)
    ]
    return ciede2000(lab[0], lab[1])


def display_srgb(bands: np.ndarray, band_centers_nm: np.ndarray, exposure_ev: float) -> np.ndarray:
    """sRGB-encoded values in [0, 1], (H, W, 3): what the viewer shows at ``exposure_ev`` with clamp."""
    linear = _exposed_xyz(bands, band_centers_nm, exposure_ev) @ XYZ_TO_LINEAR_SRGB.T
    return srgb_encode(np.clip(linear, 0.0, 1.0))


def flip_map(
    reference: np.ndarray, sample: np.ndarray, band_centers_nm: np.ndarray, exposure_ev: float
) -> np.ndarray:
    """Per-pixel LDR-ꟻLIP error in [0, 1] of two (H, W, B) band images displayed at ``exposure_ev``."""
    import flip_evaluator

    error, _, _ = flip_evaluator.evaluate(
        display_srgb(reference, band_centers_nm, exposure_ev).astype(np.float32),
        display_srgb(sample, band_centers_nm, exposure_ev).astype(np.float32),
        "LDR",
        inputsRGB=True,
        applyMagma=False,
        computeMeanError=False,
    )
    return np.asarray(error, dtype=np.float64)[..., 0]


def perceptual_map(
    metric: str,
    reference: np.ndarray,
    sample: np.ndarray,
    band_centers_nm: np.ndarray,
    exposure_ev: float,
) -> np.ndarray:
    """``de2000`` or ``flip`` per-pixel map (H, W) of two band images of the same layout."""
    if reference.shape != sample.shape:
        raise InputError(f"b: image is {sample.shape}, a is {reference.shape}; compare needs equal layouts")
    if metric == "de2000":
        return delta_e00_map(reference, sample, band_centers_nm, exposure_ev)
    if metric == "flip":
        return flip_map(reference, sample, band_centers_nm, exposure_ev)
    raise InputError(f"mode: must be one of {', '.join(PERCEPTUAL_METRICS)}, got {metric!r}")


def map_statistics(values: np.ndarray) -> dict[str, float]:
    """Mean, 95th percentile and maximum of a per-pixel map over its finite values."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return {"mean": math.nan, "p95": math.nan, "max": math.nan}
    return {
        "mean": float(finite.mean()),
        "p95": float(np.percentile(finite, 95.0)),
        "max": float(finite.max()),
    }
