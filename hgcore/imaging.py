"""Display transforms shared by the renderer's preview, the service's viewer endpoints and the viewer.

NumPy only (the service imports it). The viewer's JavaScript implements the same formulas; tests compare
canvas pixels with :func:`display_rgb8` of the same data.

* exposure: linear × 2^EV;
* tone mapping operators on linear sRGB: ``clamp`` (identity, then clip), ``reinhard`` (x/(1+x) per
  channel) and ``aces`` (Narkowicz 2015 fit of the ACES filmic curve, (x(2.51x+0.03))/(x(2.43x+0.59)+0.14));
* the sRGB transfer curve (IEC 61966-2-1) and 8-bit quantisation (round half up).
"""

from __future__ import annotations

import math

import numpy as np

from hgcore.errors import InputError

TONE_MAPS = ("clamp", "reinhard", "aces")
REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def tone_map(linear_rgb: np.ndarray, operator: str = "clamp") -> np.ndarray:
    """Tone-mapped linear values in [0, 1] (before the transfer curve)."""
    x = np.maximum(np.asarray(linear_rgb, dtype=np.float64), 0.0)
    if operator == "clamp":
        mapped = x
    elif operator == "reinhard":
        mapped = x / (1.0 + x)
    elif operator == "aces":
        mapped = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
    else:
        raise InputError(f"tonemap: must be one of {', '.join(TONE_MAPS)}, got {operator!r}")
    return np.clip(mapped, 0.0, 1.0)


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve of values in [0, 1]."""
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1.0 / 2.4) - 0.055)


def display_rgb8(linear_rgb: np.ndarray, exposure_ev: float = 0.0, operator: str = "clamp") -> np.ndarray:
    """8-bit sRGB for display: exposure, tone mapping, transfer curve, round half up.

    A NaN channel (a renderer sample gone wrong) displays as 0, as the viewer's ``Uint8ClampedArray``
    stores NaN; casting NaN to uint8 is undefined in NumPy (platform-dependent, with a RuntimeWarning)."""
    if not math.isfinite(exposure_ev):
        raise InputError(f"ev: must be finite, got {exposure_ev}")
    encoded = srgb_encode(tone_map(np.asarray(linear_rgb, dtype=np.float64) * 2.0**exposure_ev, operator))
    return np.floor(np.where(np.isnan(encoded), 0.0, encoded) * 255.0 + 0.5).astype(np.uint8)


def _finite(values: np.ndarray) -> np.ndarray:
    """The finite entries of ``values`` (flattened): exposure statistics ignore NaN/inf pixels, which
    would otherwise make every quantile NaN and drop the whole image to the 0 EV fallback."""
    flat = np.ravel(values)
    return flat[np.isfinite(flat)]


def auto_exposure_ev(linear_rgb: np.ndarray, percentile: float = 99.0) -> float:
    """EV that maps the given percentile of the finite pixels' luminance to 1 (0 for a black image)."""
    luminance = _finite(np.asarray(linear_rgb, dtype=np.float64) @ REC709_LUMINANCE)
    high = float(np.percentile(luminance, percentile)) if luminance.size else 0.0
    return 0.0 if high <= 0 or not math.isfinite(high) else -math.log2(high)


#: The share of pixels whose brightest channel the preview lets clip (``preview_exposure_ev``).
PREVIEW_CLIPPED_FRACTION = 0.002


def preview_exposure_ev(linear_rgb: np.ndarray, clipped_fraction: float = PREVIEW_CLIPPED_FRACTION) -> float:
    """EV of ``preview.png``: the (1 − clipped_fraction) quantile of each pixel's *brightest channel*
    max(R, G, B) maps to 1 (0 for a black image).

    Why the brightest channel and not luminance (``auto_exposure_ev``, the viewer's default): a saturated
    highlight — an interference colour, a diffraction order — has a luminance well below its largest
    channel, so mapping luminance to 1 clips that channel and washes the colour out towards white. With
    this rule at most ``clipped_fraction`` of the pixels (0.2 %: the emitter seen directly, glints) have
    any channel clipped, and every other pixel keeps its hue and saturation under the ``clamp`` tone map.
    Non-finite pixels are left out of the quantile (see ``_finite``).
    """
    brightest = _finite(np.max(np.maximum(np.asarray(linear_rgb, dtype=np.float64), 0.0), axis=-1))
    high = float(np.quantile(brightest, 1.0 - clipped_fraction)) if brightest.size else 0.0
    return 0.0 if high <= 0 or not math.isfinite(high) else -math.log2(high)
