"""Emission spectra and CIE 1931 colour matching (NumPy; XYZ ↔ sRGB lives in ``hgcore.colour``).

* Planck's law, spectral radiance per unit wavelength in W·m⁻²·sr⁻¹·nm⁻¹:
  B_λ(T) = 2hc²/λ⁵ · 1/(exp(hc/(λ k_B T)) − 1), with λ in m and the result scaled by 10⁻⁹ m/nm (CODATA 2018
  exact h, c, k_B).
* CIE standard illuminants D65 and FL1–FL12 (relative spectral power, D65 = 100 at 560 nm) and the CIE 1931
  2° colour-matching functions x̄, ȳ, z̄ (1 nm, 360–830 nm), from the CSV files in ``hgcore/optics/data``
  (CIE 15:2004; ISO 11664-1/-2 = CIE S 014-1/-2; generated once with colour-science, see the file headers).
  Tables are linearly interpolated and are 0 outside their tabulated range.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from hgcore.errors import InputError

DATA_DIR = Path(__file__).resolve().parent / "data"

PLANCK_J_S = 6.62607015e-34
SPEED_OF_LIGHT_M_PER_S = 299792458.0
BOLTZMANN_J_PER_K = 1.380649e-23

ILLUMINANTS: tuple[str, ...] = ("d65", *(f"f{index}" for index in range(1, 13)))


def load_data_csv(filename: str) -> tuple[tuple[str, ...], np.ndarray]:
    """Column names and values of a ``hgcore/optics/data`` CSV ('#' comment lines, then a header row)."""
    lines = (DATA_DIR / filename).read_text(encoding="utf-8").splitlines()
    body = [line for line in lines if line.strip() and not line.startswith("#")]
    names = tuple(body[0].split(","))
    values = np.array([[float(field) for field in line.split(",")] for line in body[1:]])
    return names, values


def _validated_wavelengths(wavelength_nm: float | np.ndarray) -> np.ndarray:
    wavelengths = np.asarray(wavelength_nm, dtype=float)
    if not np.all(np.isfinite(wavelengths)) or np.any(wavelengths <= 0.0):
        raise InputError("wavelength_nm: must be finite and > 0 nm")
    return wavelengths


def planck_radiance(wavelength_nm: float | np.ndarray, temperature_k: float) -> np.ndarray:
    """Blackbody spectral radiance B_λ(T) in W·m⁻²·sr⁻¹·nm⁻¹."""
    if not (math.isfinite(temperature_k) and temperature_k > 0.0):
        raise InputError(f"temperature_k: must be finite and > 0 K, got {temperature_k}")
    wavelength_m = _validated_wavelengths(wavelength_nm) * 1e-9
    exponent = PLANCK_J_S * SPEED_OF_LIGHT_M_PER_S / (wavelength_m * BOLTZMANN_J_PER_K * temperature_k)
    with np.errstate(over="ignore"):  # far below the peak expm1 overflows to inf and B_λ correctly to 0
        per_metre = 2.0 * PLANCK_J_S * SPEED_OF_LIGHT_M_PER_S**2 / wavelength_m**5 / np.expm1(exponent)
    return per_metre * 1e-9


@functools.cache
def _illuminant_table(name: str) -> np.ndarray:
    file_name = "cie_illuminant_d65.csv" if name == "d65" else f"cie_illuminant_fl{name[1:]}.csv"
    return load_data_csv(file_name)[1]


@functools.cache
def _cmf_table() -> np.ndarray:
    return load_data_csv("cie1931_2deg_cmf.csv")[1]


def cie_illuminant(name: str, wavelength_nm: float | np.ndarray) -> np.ndarray:
    """Relative spectral power of CIE illuminant ``name`` ('d65', 'f1' … 'f12'; 'fl2' also accepted)."""
    key = name.strip().lower().replace("fl", "f")
    if key not in ILLUMINANTS:
        raise InputError(f"name: unknown illuminant {name!r}; choose one of {', '.join(ILLUMINANTS)}")
    table = _illuminant_table(key)
    return np.interp(_validated_wavelengths(wavelength_nm), table[:, 0], table[:, 1], left=0.0, right=0.0)


def cie_cmf(wavelength_nm: float | np.ndarray) -> np.ndarray:
    """CIE 1931 2° x̄, ȳ, z̄ at ``wavelength_nm``; shape (..., 3)."""
    wavelengths = _validated_wavelengths(wavelength_nm)
    table = _cmf_table()
    return np.stack(
        [np.interp(wavelengths, table[:, 0], table[:, i], left=0.0, right=0.0) for i in (1, 2, 3)], axis=-1
    )


def spectrum_values(kind: str, wavelength_nm: float | np.ndarray, **params: float) -> np.ndarray:
    """Spectrum of ``kind`` at ``wavelength_nm``.

    ``blackbody`` (``temperature_k``; W·m⁻²·sr⁻¹·nm⁻¹, optional ``scale``), a CIE illuminant name
    (``d65``, ``f1`` … ``f12``; relative units, optional ``scale``), or ``equal_energy`` (CIE illuminant E,
    value ``scale``, default 1).
    """
    key = kind.strip().lower()
    scale = float(params.pop("scale", 1.0))
    if not math.isfinite(scale) or scale < 0.0:
        raise InputError(f"scale: must be finite and ≥ 0, got {scale}")
    if key == "blackbody":
        if "temperature_k" not in params:
            raise InputError("temperature_k: required for a blackbody spectrum")
        values = planck_radiance(wavelength_nm, float(params.pop("temperature_k")))
    elif key == "equal_energy":
        values = np.ones_like(_validated_wavelengths(wavelength_nm))
    else:
        try:
            values = cie_illuminant(key, wavelength_nm)
        except ValueError:
            choices = ", ".join(("blackbody", "equal_energy", *ILLUMINANTS))
            raise InputError(f"kind: unknown spectrum {kind!r}; choose one of {choices}") from None
    if params:
        raise InputError(f"{next(iter(params))}: not a parameter of the {key} spectrum")
    return scale * values


def spectrum_to_xyz(wavelength_nm: np.ndarray, values: np.ndarray) -> np.ndarray:
    """CIE XYZ = ∫ S(λ) (x̄, ȳ, z̄) dλ by the trapezoid rule over the given samples (λ in nm, ascending)."""
    wavelengths = _validated_wavelengths(wavelength_nm)
    if wavelengths.ndim != 1 or wavelengths.size < 2 or not np.all(np.diff(wavelengths) > 0.0):
        raise InputError("wavelength_nm: must be a 1-D, strictly increasing grid of at least 2 wavelengths")
    weights = cie_cmf(wavelengths) * np.asarray(values, dtype=float)[..., None]
    return np.trapezoid(weights, wavelengths, axis=-2)
