"""CIEDE2000 colour differences of linear-sRGB images (for the Fig. 9 mode comparison).

* Linear sRGB → CIE XYZ: the inverse of ``hgcore.optics.spectra.XYZ_TO_LINEAR_SRGB`` (IEC 61966-2-1), i.e.
  exactly the transform the renderer used to make its RGB channels; the D65 reference white is the XYZ of
  the grey RGB = (w, w, w), w = ``white_level``.
* XYZ → CIELAB (CIE 15:2004): L* = 116 f(Y/Y_n) − 16, a* = 500 (f(X/X_n) − f(Y/Y_n)),
  b* = 200 (f(Y/Y_n) − f(Z/Z_n)), f(t) = t^{1/3} above (6/29)³ and t/(3·(6/29)²) + 4/29 below.
* ΔE₀₀: Sharma, Wu & Dalal, "The CIEDE2000 color-difference formula: implementation notes, supplementary
  test data, and mathematical observations", Color Res. Appl. 30(1), 2005, Eqs. (1)–(22), k_L = k_C = k_H = 1,
  including their conventions for achromatic colours (h' = 0, mean hue = sum) and hue wrap-around.
"""

from __future__ import annotations

import numpy as np

from hgcore.optics.spectra import XYZ_TO_LINEAR_SRGB

LINEAR_SRGB_TO_XYZ = np.linalg.inv(XYZ_TO_LINEAR_SRGB)
LAB_EPSILON = (6.0 / 29.0) ** 3
TWENTY_FIVE_TO_SEVENTH = 25.0**7


def linear_srgb_to_lab(rgb: np.ndarray, white_level: float) -> np.ndarray:
    """CIELAB (D65) of linear sRGB values (last axis 3); the grey (w, w, w), w = ``white_level``, is white."""
    if not white_level > 0.0:
        raise ValueError(f"white_level: must be positive, got {white_level}")
    xyz = np.asarray(rgb, dtype=float) @ LINEAR_SRGB_TO_XYZ.T
    white = LINEAR_SRGB_TO_XYZ @ np.full(3, white_level)
    t = xyz / white
    f = np.where(
        t > LAB_EPSILON, np.cbrt(np.maximum(t, LAB_EPSILON)), t / (3.0 * (6.0 / 29.0) ** 2) + 4.0 / 29.0
    )
    lightness = 116.0 * f[..., 1] - 16.0
    return np.stack([lightness, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def ciede2000(lab_1: np.ndarray, lab_2: np.ndarray) -> np.ndarray:
    """ΔE₀₀ between CIELAB colours (last axis 3), element-wise (Sharma et al. 2005)."""
    l_1, a_1, b_1 = np.moveaxis(np.asarray(lab_1, dtype=float), -1, 0)
    l_2, a_2, b_2 = np.moveaxis(np.asarray(lab_2, dtype=float), -1, 0)
    # Eqs. (2)–(7): a' stretched by G, C' and h' (degrees in [0, 360), 0 for a' = b = 0).
    chroma_mean = 0.5 * (np.hypot(a_1, b_1) + np.hypot(a_2, b_2))
    g = 0.5 * (1.0 - np.sqrt(chroma_mean**7 / (chroma_mean**7 + TWENTY_FIVE_TO_SEVENTH)))
    a_1p, a_2p = (1.0 + g) * a_1, (1.0 + g) * a_2
    c_1p, c_2p = np.hypot(a_1p, b_1), np.hypot(a_2p, b_2)
    h_1p = np.where((a_1p == 0) & (b_1 == 0), 0.0, np.degrees(np.arctan2(b_1, a_1p)) % 360.0)
    h_2p = np.where((a_2p == 0) & (b_2 == 0), 0.0, np.degrees(np.arctan2(b_2, a_2p)) % 360.0)
    # Eqs. (8)–(11): differences, with the hue difference wrapped into (−180°, 180°].
    chromatic = c_1p * c_2p != 0
    delta_l = l_2 - l_1
    delta_c = c_2p - c_1p
    dh = h_2p - h_1p
    dh = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    dh = np.where(chromatic, dh, 0.0)
    delta_h = 2.0 * np.sqrt(c_1p * c_2p) * np.sin(np.radians(dh) / 2.0)
    # Eqs. (12)–(14): means; the mean hue takes the shorter arc (and is the sum for achromatic pairs).
    l_mean = 0.5 * (l_1 + l_2)
    c_mean = 0.5 * (c_1p + c_2p)
    h_sum = h_1p + h_2p
    h_mean = np.where(
        np.abs(h_1p - h_2p) <= 180.0,
        0.5 * h_sum,
        np.where(h_sum < 360.0, 0.5 * (h_sum + 360.0), 0.5 * (h_sum - 360.0)),
    )
    h_mean = np.where(chromatic, h_mean, h_sum)
    # Eqs. (15)–(22): weighting functions and the rotation term.
    t = (
        1.0
        - 0.17 * np.cos(np.radians(h_mean - 30.0))
        + 0.24 * np.cos(np.radians(2.0 * h_mean))
        + 0.32 * np.cos(np.radians(3.0 * h_mean + 6.0))
        - 0.20 * np.cos(np.radians(4.0 * h_mean - 63.0))
    )
    delta_theta = 30.0 * np.exp(-(((h_mean - 275.0) / 25.0) ** 2))
    r_c = 2.0 * np.sqrt(c_mean**7 / (c_mean**7 + TWENTY_FIVE_TO_SEVENTH))
    s_l = 1.0 + 0.015 * (l_mean - 50.0) ** 2 / np.sqrt(20.0 + (l_mean - 50.0) ** 2)
    s_c = 1.0 + 0.045 * c_mean
    s_h = 1.0 + 0.015 * c_mean * t
    r_t = -np.sin(np.radians(2.0 * delta_theta)) * r_c
    term_l, term_c, term_h = delta_l / s_l, delta_c / s_c, delta_h / s_h
    return np.sqrt(term_l**2 + term_c**2 + term_h**2 + r_t * term_c * term_h)
