"""Spectral lookup tables for the ``hg_path`` integrator.

Each camera sample carries four wavelengths (Mitsuba's spectral variants are four-wide); how they are drawn
and what each is worth in the bands is ``worker.render.wavelength_sampling``'s (uniform:
λ_j = λ_min + Λ·frac(u + j/4), band b estimated per sample as (1/4) Σ_j L(λ_j)·1_b(λ_j)·Λ/Δ_b, an unbiased
estimator of the band-averaged spectral radiance (1/Δ_b)∫_b L dλ in W·m⁻²·sr⁻¹·nm⁻¹).

Material spectra (reflectances, refractive indices) live in one flat table sampled on a regular grid
(``GRID_MIN_NM`` … ``GRID_MAX_NM`` every ``GRID_STEP_NM``) and are linearly interpolated in the kernel.

The CIE 1931 colour-matching functions the kernels weight samples with (luminance, XYZ) are Mitsuba's, in a
table of our own (``cie1931_table``): a frozen render pass (``renderer``) must name every array its kernels
read, and Mitsuba's table is a global that no frozen function can reach.
"""

from __future__ import annotations

import numpy as np

from hgcore.errors import InputError

GRID_MIN_NM = 200.0
GRID_MAX_NM = 2500.0
GRID_STEP_NM = 5.0
GRID_SIZE = round((GRID_MAX_NM - GRID_MIN_NM) / GRID_STEP_NM) + 1


def grid_wavelengths_nm() -> np.ndarray:
    """The wavelengths (nm) of the spectral lookup grid."""
    return GRID_MIN_NM + GRID_STEP_NM * np.arange(GRID_SIZE)


class SpectralTable:
    """Builds the flat (spectrum id × grid) table that kernels interpolate."""

    def __init__(self) -> None:
        self._rows: list[np.ndarray] = []
        self._index: dict[bytes, int] = {}

    def add(self, values_on_grid: np.ndarray) -> int:
        """Register a spectrum sampled on ``grid_wavelengths_nm()``; identical spectra share one id."""
        row = np.asarray(values_on_grid, dtype=np.float32)
        if row.shape != (GRID_SIZE,):
            raise InputError(f"spectrum: expected {GRID_SIZE} grid samples, got shape {row.shape}")
        if not np.all(np.isfinite(row)):
            raise InputError("spectrum: values must be finite")
        key = row.tobytes()
        if key not in self._index:
            self._index[key] = len(self._rows)
            self._rows.append(row)
        return self._index[key]

    def add_constant(self, value: float) -> int:
        return self.add(np.full(GRID_SIZE, value, dtype=np.float32))

    def flat(self) -> np.ndarray:
        if not self._rows:
            return np.zeros(GRID_SIZE, dtype=np.float32)
        return np.concatenate(self._rows)


# Mitsuba's CIE 1931 2° table: MI_CIE_SAMPLES nodes from MI_CIE_MIN to MI_CIE_MAX (nm), every 5 nm.
CIE_MIN_NM = 360.0
CIE_MAX_NM = 830.0
CIE_SAMPLES = 95


def cie1931_table(mi):
    """x̄, ȳ, z̄ of Mitsuba's CIE 1931 table at its nodes, flattened as [x̄ nodes, ȳ nodes, z̄ nodes] (one
    mi.Float): read through ``mi.cie1931_xyz`` at the nodes, where its interpolation returns them exactly."""
    nodes = np.linspace(CIE_MIN_NM, CIE_MAX_NM, CIE_SAMPLES)
    values = mi.cie1931_xyz(mi.Float(nodes))
    return mi.Float(np.concatenate([np.asarray(component) for component in values]).astype(np.float32))


def cie1931_xyz(mi, table, wavelengths_nm):
    """(x̄, ȳ, z̄) at ``wavelengths_nm`` (mi.Float) from ``cie1931_table``, interpolated as Mitsuba's
    ``cie1931_xyz`` does (the same floats: tests/integrator/test_frozen_passes.py); 0 outside the table."""
    import drjit as dr

    position = (wavelengths_nm - CIE_MIN_NM) * ((CIE_SAMPLES - 1) / (CIE_MAX_NM - CIE_MIN_NM))
    inside = (wavelengths_nm >= CIE_MIN_NM) & (wavelengths_nm <= CIE_MAX_NM)
    lower = dr.clip(mi.UInt32(position), 0, CIE_SAMPLES - 2)
    upper_weight = position - mi.Float(lower)
    lower_weight = 1.0 - upper_weight
    result = []
    for component in range(3):
        base = component * CIE_SAMPLES + lower
        low = dr.gather(mi.Float, table, base, inside)
        high = dr.gather(mi.Float, table, base + 1, inside)
        result.append(dr.select(inside, dr.fma(lower_weight, low, upper_weight * high), 0.0))
    return tuple(result)


def lookup(mi, table, spectrum_id, wavelengths, active=True):
    """Interpolate spectrum ``spectrum_id`` (UInt32 per lane) of ``table`` at ``wavelengths`` (nm) in the
    lanes ``active`` (0 elsewhere)."""
    import drjit as dr

    result = mi.Spectrum(0.0)
    base = spectrum_id * GRID_SIZE
    for j in range(len(wavelengths)):
        position = dr.clip((wavelengths[j] - GRID_MIN_NM) / GRID_STEP_NM, 0.0, GRID_SIZE - 1.001)
        index = mi.UInt32(dr.floor(position))
        fraction = position - mi.Float(index)
        lower = dr.gather(mi.Float, table, base + index, active)
        upper = dr.gather(mi.Float, table, base + index + 1, active)
        result[j] = dr.lerp(lower, upper, fraction)
    return result
