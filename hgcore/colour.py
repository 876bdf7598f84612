"""Colour science for comparing renders: band spectra or linear sRGB → CIE XYZ → CIELAB (D65) → CIEDE2000.

* XYZ of a band image: X = Σ_b L_b ∫_band x̄(λ) dλ (and likewise Y, Z) for equal-width bands given by their
  centres, with the CIE 1931 2° colour-matching functions of ``hgcore.optics.spectra.cie_cmf`` (NumPy only).
  Units: L_b in W·m⁻²·sr⁻¹·nm⁻¹ gives XYZ in W·m⁻²·sr⁻¹ (scaled later by the reference white).
* CIELAB (CIE 15:2004 §8.2.1): L* = 116 f(Y/Yn) − 16, a* = 500 [f(X/Xn) − f(Y/Yn)], b* = 200 [f(Y/Yn) −
  f(Z/Zn)], f(t) = t^⅓ above (6/29)³ and t/(3 (6/29)²) + 4/29 below; white (Xn, Yn, Zn) = D65 scaled to Yn.
* CIEDE2000 ΔE₀₀ (CIE 142-2001) in the implementation of Sharma, Wu & Dalal, Color Res. Appl. 30(1), 2005,
  Eqs. (1)–(22), with k_L = k_C = k_H = 1. Hue angles are in degrees; the hue-difference and mean-hue
  branches compare |h′₁ − h′₂| with 180° up to 1e-9° because that difference is exactly 180° in exact
  arithmetic for the antipodal pairs of Sharma's table (pair 14), and rounding must not pick a branch.
* Linear sRGB ↔ XYZ: IEC 61966-2-1:1999, computed at full precision from the primaries' and the D65
  white's chromaticities (the standard's printed matrices are these rounded); one pair for the renderer's
  RGB channels, the viewer and the regression metrics.
"""

from __future__ import annotations

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.spectra import cie_cmf

SRGB_PRIMARIES_XY: np.ndarray = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])
"""IEC 61966-2-1 (ITU-R BT.709) chromaticities of the R, G, B primaries."""
D65_WHITE_XY: tuple[float, float] = (0.3127, 0.3290)
"""The sRGB white point's chromaticity (IEC 61966-2-1 Table 1)."""


def _xy_to_xyz(x: float, y: float) -> np.ndarray:
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def _rgb_to_xyz_matrix(primaries_xy: np.ndarray, white_xy: tuple[float, float]) -> np.ndarray:
    """The matrix whose columns are the primaries' XYZ, scaled so that RGB = (1, 1, 1) is the white."""
    primaries = np.stack([_xy_to_xyz(x, y) for x, y in primaries_xy], axis=1)
    return primaries * np.linalg.solve(primaries, _xy_to_xyz(*white_xy))


D65_WHITE_XYZ: np.ndarray = _xy_to_xyz(*D65_WHITE_XY)
"""D65 white of sRGB normalised to Y = 1 (0.950456, 1, 1.089058): the XYZ of linear sRGB (1, 1, 1)."""
LINEAR_SRGB_TO_XYZ: np.ndarray = _rgb_to_xyz_matrix(SRGB_PRIMARIES_XY, D65_WHITE_XY)
"""Linear sRGB → CIE XYZ at full float64 precision from the primaries and white (row 1 = 0.4123908,
0.3575843, 0.1804808; IEC 61966-2-1 prints it rounded to 4 decimals)."""
XYZ_TO_LINEAR_SRGB: np.ndarray = np.linalg.inv(LINEAR_SRGB_TO_XYZ)
"""CIE XYZ → linear sRGB, the exact inverse (row 1 = 3.2409699, −1.5373832, −0.4986108)."""

_HUE_TIE_DEG = 1e-9
_LAB_EPSILON = (6.0 / 29.0) ** 3


def band_edges_xyz_weights(edges_nm: np.ndarray, step_nm: float = 1.0) -> np.ndarray:
    """∫_band (x̄, ȳ, z̄) dλ for bands between consecutive ``edges_nm`` (nm); shape (B, 3), in nm."""
    edges = np.asarray(edges_nm, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.diff(edges) > 0.0):
        raise InputError("edges_nm: must be at least 2 strictly increasing band edges")
    weights = np.zeros((edges.size - 1, 3))
    for band in range(edges.size - 1):
        low_nm, high_nm = edges[band], edges[band + 1]
        # Both edges are nodes (a band of 12.5 nm has 13 intervals of 0.96 nm, not 12 of 1 nm and a gap).
        nodes = max(2, int(np.ceil((high_nm - low_nm) / step_nm - 1e-9)) + 1)
        grid_nm = np.linspace(low_nm, high_nm, nodes)
        weights[band] = np.trapezoid(cie_cmf(grid_nm), grid_nm, axis=0)
    return weights


def band_xyz_weights(band_centers_nm: np.ndarray, step_nm: float = 1.0) -> np.ndarray:
    """∫_band (x̄, ȳ, z̄) dλ for equal-width bands given by their centres (nm); shape (B, 3).

    The band edges are the centres ± half their spacing, as in the renderer's ``BandLayout``.
    """
    centers_nm = np.asarray(band_centers_nm, dtype=float)
    if centers_nm.ndim != 1 or centers_nm.size < 2 or not np.all(np.diff(centers_nm) > 0.0):
        raise InputError("band_centers_nm: must be at least 2 strictly increasing band centres")
    half_width_nm = 0.5 * float(np.mean(np.diff(centers_nm)))
    edges_nm = np.append(centers_nm - half_width_nm, centers_nm[-1] + half_width_nm)
    return band_edges_xyz_weights(edges_nm, step_nm)


def y_bar_integral_nm() -> float:
    """∫ ȳ(λ) dλ over the CIE 1931 table (nm): the Y of a unit equal-energy spectrum before normalisation."""
    grid_nm = np.arange(360.0, 830.5, 1.0)
    return float(np.trapezoid(cie_cmf(grid_nm)[:, 1], grid_nm))


def image_xyz_weights(edges_nm: np.ndarray) -> np.ndarray:
    """XYZ per unit band radiance for bands between ``edges_nm``, shape (B, 3): ∫_band (x̄, ȳ, z̄) dλ / ∫ ȳ dλ,
    the image's normalisation (a unit equal-energy spectrum has Y = 1, Mitsuba's film convention)."""
    return band_edges_xyz_weights(edges_nm) / y_bar_integral_nm()


def bands_to_xyz(band_values: np.ndarray, band_centers_nm: np.ndarray) -> np.ndarray:
    """CIE XYZ of band radiances ``band_values`` (..., B) with band centres in nm; shape (..., 3)."""
    return np.asarray(band_values, dtype=float) @ band_xyz_weights(band_centers_nm)


def radiance_xyz(band_values: np.ndarray, band_centers_nm: np.ndarray) -> np.ndarray:
    """CIE XYZ of (..., B) band radiances on the scale of the renderer's linear sRGB: divided by ∫ȳ dλ, so a
    unit equal-energy spectrum has Y = 1 and Y is the luminance of an EXR's R, G, B."""
    return bands_to_xyz(band_values, band_centers_nm) / y_bar_integral_nm()


def xyz_to_lab(xyz: np.ndarray, white_xyz: np.ndarray) -> np.ndarray:
    """CIELAB L*, a*, b* of ``xyz`` (..., 3) relative to the white ``white_xyz`` (3,), same units."""
    white = np.asarray(white_xyz, dtype=float)
    if white.shape != (3,) or np.any(white <= 0.0):
        raise InputError("white_xyz: must be three positive tristimulus values")
    ratio = np.asarray(xyz, dtype=float) / white
    f = np.where(ratio > _LAB_EPSILON, np.cbrt(ratio), ratio / (3.0 * (6.0 / 29.0) ** 2) + 4.0 / 29.0)
    lightness = 116.0 * f[..., 1] - 16.0
    return np.stack([lightness, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def linear_srgb_to_xyz(linear_rgb: np.ndarray) -> np.ndarray:
    """CIE XYZ (D65, Y = 1 for white) of linear sRGB values, last axis of size 3."""
    values = np.asarray(linear_rgb, dtype=float)
    if values.shape[-1] != 3:
        raise InputError(f"linear_rgb: last axis must have size 3, got shape {values.shape}")
    return values @ LINEAR_SRGB_TO_XYZ.T


def xyz_to_linear_srgb(xyz: np.ndarray) -> np.ndarray:
    """Linear sRGB (no transfer curve) of CIE XYZ values, last axis of size 3."""
    values = np.asarray(xyz, dtype=float)
    if values.shape[-1] != 3:
        raise InputError(f"xyz: last axis must have size 3, got shape {values.shape}")
    return values @ XYZ_TO_LINEAR_SRGB.T


def linear_srgb_to_lab(linear_rgb: np.ndarray, white_level: float = 1.0) -> np.ndarray:
    """CIELAB (D65) of linear sRGB values (last axis 3); the grey (w, w, w), w = ``white_level``, is white."""
    if not white_level > 0.0:
        raise InputError(f"white_level: must be positive, got {white_level}")
    return xyz_to_lab(linear_srgb_to_xyz(linear_rgb), D65_WHITE_XYZ * white_level)


def ciede2000(lab_reference: np.ndarray, lab_sample: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference ΔE₀₀ between CIELAB arrays of equal shape (..., 3) (Sharma et al.
    2005); symmetric in its arguments."""
    lab_1, lab_2 = np.asarray(lab_reference, dtype=float), np.asarray(lab_sample, dtype=float)
    if lab_1.shape != lab_2.shape or lab_1.shape[-1:] != (3,):
        raise InputError(
            f"lab_sample: shape {lab_2.shape} must equal lab_reference's {lab_1.shape} with a last axis "
            "of size 3 (L*, a*, b*)"
        )
    l_1, a_1, b_1 = np.moveaxis(lab_1, -1, 0)
    l_2, a_2, b_2 = np.moveaxis(lab_2, -1, 0)
    # Eqs. (2)-(7): a' rescaled by G so that near-neutral colours get a less compressed hue.
    chroma_mean_7 = ((np.hypot(a_1, b_1) + np.hypot(a_2, b_2)) / 2.0) ** 7
    g = 0.5 * (1.0 - np.sqrt(chroma_mean_7 / (chroma_mean_7 + 25.0**7)))
    a_1p, a_2p = (1.0 + g) * a_1, (1.0 + g) * a_2
    c_1p, c_2p = np.hypot(a_1p, b_1), np.hypot(a_2p, b_2)
    h_1p = np.where(c_1p == 0.0, 0.0, np.degrees(np.arctan2(b_1, a_1p)) % 360.0)
    h_2p = np.where(c_2p == 0.0, 0.0, np.degrees(np.arctan2(b_2, a_2p)) % 360.0)
    # Eqs. (8)-(11): differences; the hue difference wraps into [-180, 180].
    chroma_product = c_1p * c_2p
    dh = h_2p - h_1p
    dh = np.where(dh > 180.0 + _HUE_TIE_DEG, dh - 360.0, np.where(dh < -180.0 - _HUE_TIE_DEG, dh + 360.0, dh))
    dh = np.where(chroma_product == 0.0, 0.0, dh)
    d_lp, d_cp = l_2 - l_1, c_2p - c_1p
    d_hp = 2.0 * np.sqrt(chroma_product) * np.sin(np.radians(dh / 2.0))
    # Eqs. (12)-(21): means, weighting functions and the rotation term.
    l_mean, c_mean = (l_1 + l_2) / 2.0, (c_1p + c_2p) / 2.0
    h_sum = h_1p + h_2p
    h_mean = np.where(
        np.abs(h_1p - h_2p) <= 180.0 + _HUE_TIE_DEG,
        h_sum / 2.0,
        np.where(h_sum < 360.0, (h_sum + 360.0) / 2.0, (h_sum - 360.0) / 2.0),
    )
    h_mean = np.where(chroma_product == 0.0, h_sum, h_mean)
    t = (
        1.0
        - 0.17 * np.cos(np.radians(h_mean - 30.0))
        + 0.24 * np.cos(np.radians(2.0 * h_mean))
        + 0.32 * np.cos(np.radians(3.0 * h_mean + 6.0))
        - 0.20 * np.cos(np.radians(4.0 * h_mean - 63.0))
    )
    d_theta = 30.0 * np.exp(-(((h_mean - 275.0) / 25.0) ** 2))
    c_mean_7 = c_mean**7
    r_c = 2.0 * np.sqrt(c_mean_7 / (c_mean_7 + 25.0**7))
    s_l = 1.0 + 0.015 * (l_mean - 50.0) ** 2 / np.sqrt(20.0 + (l_mean - 50.0) ** 2)
    s_c = 1.0 + 0.045 * c_mean
    s_h = 1.0 + 0.015 * c_mean * t
    r_t = -np.sin(np.radians(2.0 * d_theta)) * r_c
    # Eq. (22).
    return np.sqrt(
        (d_lp / s_l) ** 2 + (d_cp / s_c) ** 2 + (d_hp / s_h) ** 2 + r_t * (d_cp / s_c) * (d_hp / s_h)
    )
