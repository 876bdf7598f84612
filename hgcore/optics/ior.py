"""Spectral complex refractive index η(λ) = n(λ) + iκ(λ) of common metals and glasses (NumPy).

Metals (silver, gold, copper, aluminium): tabulated n, κ in ``hgcore/optics/data/ior_<metal>.csv`` from
E. D. Palik (ed.), *Handbook of Optical Constants of Solids*, Academic Press, 1985, via the LuxPop database,
as distributed with Mitsuba 3 (``data/ior/*.spd``); linearly interpolated in wavelength, valid only inside
the tabulated range (≈ 299–886 nm).

Dielectrics (κ = 0) by the Sellmeier formula n² = 1 + Σ_i B_i λ²/(λ² − C_i), λ in µm, C_i in µm²:
  BK7 (Schott N-BK7 datasheet, 0.3–2.5 µm); fused silica (I. H. Malitson, J. Opt. Soc. Am. 55, 1205, 1965;
  0.21–3.71 µm); water at 20 °C (M. Daimon & A. Masumura, Appl. Opt. 46, 3811, 2007; 0.182–1.129 µm).

``spectral_ior`` validates its wavelengths (nm) and raises ``ValueError`` outside a material's range;
``ior_table`` samples a grid for the lookup tables that Dr.Jit kernels interpolate.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.spectra import load_data_csv

# The project-wide wavelength window (issue 2): anything outside is rejected before a material is consulted.
MIN_WAVELENGTH_NM = 200.0
MAX_WAVELENGTH_NM = 2500.0


@dataclass(frozen=True)
class SellmeierGlass:
    """Sellmeier coefficients B_i (dimensionless), C_i (µm²) and the validity range (nm)."""

    b: tuple[float, ...]
    c_um2: tuple[float, ...]
    min_nm: float
    max_nm: float

    def index(self, wavelength_nm: np.ndarray) -> np.ndarray:
        lambda_um2 = (wavelength_nm * 1e-3) ** 2
        n_squared = 1.0 + sum(
            b * lambda_um2 / (lambda_um2 - c) for b, c in zip(self.b, self.c_um2, strict=True)
        )
        return np.sqrt(n_squared)


GLASSES: dict[str, SellmeierGlass] = {
    "bk7": SellmeierGlass(
        b=(1.03961212, 0.231792344, 1.01046945),
        c_um2=(0.00600069867, 0.0200179144, 103.560653),
        min_nm=300.0,
        max_nm=2500.0,
    ),
    "fused_silica": SellmeierGlass(
        b=(0.6961663, 0.4079426, 0.8974794),
        c_um2=(0.0684043**2, 0.1162414**2, 9.896161**2),
        min_nm=210.0,
        max_nm=2500.0,
    ),
    "water": SellmeierGlass(
        b=(5.684027565e-1, 1.726177391e-1, 2.086189578e-2, 1.130748688e-1),
        c_um2=(5.101829712e-3, 1.821153936e-2, 2.620722293e-2, 1.069792721e1),
        min_nm=200.0,
        max_nm=1129.0,
    ),
}
METALS: tuple[str, ...] = ("silver", "gold", "copper", "aluminium")
ALIASES: dict[str, str] = {
    "ag": "silver",
    "au": "gold",
    "cu": "copper",
    "al": "aluminium",
    "aluminum": "aluminium",
    "n-bk7": "bk7",
    "fusedsilica": "fused_silica",
    "fused-silica": "fused_silica",
    "silica": "fused_silica",
    "h2o": "water",
}
MATERIALS: tuple[str, ...] = METALS + tuple(GLASSES)


def canonical_material(material: str) -> str:
    """The canonical material name for ``material`` (case-insensitive, symbols and aliases accepted)."""
    key = material.strip().lower()
    key = ALIASES.get(key, key)
    if key not in MATERIALS:
        raise InputError(f"material: unknown {material!r}; choose one of {', '.join(MATERIALS)}")
    return key


@functools.cache
def metal_table(material: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wavelength_nm, n, κ) columns of a metal's CSV (read once)."""
    _, data = load_data_csv(f"ior_{material}.csv")
    return data[:, 0].copy(), data[:, 1].copy(), data[:, 2].copy()


def material_range_nm(material: str) -> tuple[float, float]:
    """The wavelength range (nm) over which ``material``'s data are valid."""
    key = canonical_material(material)
    if key in GLASSES:
        return GLASSES[key].min_nm, GLASSES[key].max_nm
    wavelengths = metal_table(key)[0]
    return float(wavelengths[0]), float(wavelengths[-1])


def spectral_ior(material: str, wavelength_nm: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, κ) of ``material`` at ``wavelength_nm`` (scalar or array, nm); κ = 0 for the dielectrics."""
    key = canonical_material(material)
    wavelengths = np.asarray(wavelength_nm, dtype=float)
    if not np.all(np.isfinite(wavelengths)):
        raise InputError("wavelength_nm: must be finite")
    if np.any(wavelengths < MIN_WAVELENGTH_NM) or np.any(wavelengths > MAX_WAVELENGTH_NM):
        raise InputError(
            f"wavelength_nm: must lie in {MIN_WAVELENGTH_NM:g}–{MAX_WAVELENGTH_NM:g} nm, "
            f"got {wavelengths.min():g}–{wavelengths.max():g}"
        )
    low_nm, high_nm = material_range_nm(key)
    if np.any(wavelengths < low_nm) or np.any(wavelengths > high_nm):
        raise InputError(
            f"wavelength_nm: {key} data cover {low_nm:.1f}–{high_nm:.1f} nm, "
            f"got {wavelengths.min():g}–{wavelengths.max():g}"
        )
    if key in GLASSES:
        return GLASSES[key].index(wavelengths), np.zeros_like(wavelengths)
    table_nm, table_n, table_kappa = metal_table(key)
    return np.interp(wavelengths, table_nm, table_n), np.interp(wavelengths, table_nm, table_kappa)


def ior_table(material: str, grid_nm: np.ndarray) -> np.ndarray:
    """Rows (wavelength_nm, n, κ) on ``grid_nm`` (strictly increasing, inside 200–2500 nm) for kernel lookups.

    A renderer tabulates every material on one shared wavelength grid that may reach beyond a material's
    data; there the end values are held (documented extrapolation), whereas :func:`spectral_ior` rejects
    such point queries.
    """
    grid = np.asarray(grid_nm, dtype=float)
    if grid.ndim != 1 or grid.size < 2 or not np.all(np.diff(grid) > 0.0):
        raise InputError("grid_nm: must be a 1-D, strictly increasing grid of at least 2 wavelengths")
    if grid.min() < MIN_WAVELENGTH_NM or grid.max() > MAX_WAVELENGTH_NM:
        raise InputError(
            f"grid_nm: must lie in {MIN_WAVELENGTH_NM:g}–{MAX_WAVELENGTH_NM:g} nm, "
            f"got {grid.min():g}–{grid.max():g}"
        )
    low_nm, high_nm = material_range_nm(material)
    n, kappa = spectral_ior(material, np.clip(grid, low_nm, high_nm))
    return np.stack([grid, n, kappa], axis=1)
