"""Spectral lookup tables for the ``hg_path`` integrator.

Each camera sample carries four wavelengths (Mitsuba's spectral variants are four-wide); how they are drawn
and what each is worth in the bands is ``worker.render.wavelength_sampling``'s (uniform:
λ_j = λ_min + Λ·frac(u + j/4), band b estimated per sample as (1/4) Σ_j L(λ_j)·1_b(λ_j)·Λ/Δ_b, an unbiased
estimator of the band-averaged spectral radiance (1/Δ_b)∫_b L dλ in W·m⁻²·sr⁻¹·nm⁻¹).

Material spectra (reflectances, refractive indices) live in one flat table sampled on a regular grid
(``GRID_MIN_NM`` … ``GRID_MAX_NM`` every ``GRID_STEP_NM``) and are linearly interpolated in the kernel.
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


def lookup(mi, table, spectrum_id, wavelengths):
    """Interpolate spectrum ``spectrum_id`` (UInt32 per lane) of ``table`` at ``wavelengths`` (nm)."""
    import drjit as dr

    result = mi.Spectrum(0.0)
    base = spectrum_id * GRID_SIZE
    for j in range(len(wavelengths)):
        position = dr.clip((wavelengths[j] - GRID_MIN_NM) / GRID_STEP_NM, 0.0, GRID_SIZE - 1.001)
        index = mi.UInt32(dr.floor(position))
        fraction = position - mi.Float(index)
        lower = dr.gather(mi.Float, table, base + index)
        upper = dr.gather(mi.Float, table, base + index + 1)
        result[j] = dr.lerp(lower, upper, fraction)
    return result
