"""What the artifacts of a render contain: file names, EXR channel names and the band layout.

Spectral channels follow Fichet, Pacanowski & Wilkie (JCGT 10(3), 2021): ``S0.<λ>nm`` with the band
centre λ in nm, six decimals and a *comma* decimal separator (``S0.550,000000nm``); their radiance is the
band-averaged spectral radiance in W·m⁻²·sr⁻¹·nm⁻¹. ``R``, ``G``, ``B`` are linear sRGB of the same scale.
Coherence diagnostics (the BRIEF's definitions) are ``coherence.<name>``, reported at
λ = ``LAMBDA_REFERENCE_NM``; ``coherence.weight`` is the fraction of a pixel's samples that carried one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hgcore.errors import InputError

# ---------------------------------------------------------------- artifact file names (one job's directory)
IMAGE_EXR = "image.exr"
VARIANCE_EXR = "variance.exr"
PREVIEW_PNG = "preview.png"
SUMMARY_JSON = "summary.json"
SCENE_JSON = "scene.json"
WORKER_LOG = "worker.log"
MANIFEST_JSON = "manifest.json"
CHUNK_PARTIAL_SUFFIX = ".npz"

SPECTRAL_ATTRIBUTES = {"spectralLayoutVersion": "1.0", "emissiveUnits": "W.m^-2.sr^-1"}
"""Header attributes of a spectral EXR (Fichet et al. 2021)."""

# ---------------------------------------------------------------------------------------- channel names
SPECTRAL_PREFIX = "S0."
RGB_CHANNELS = ("R", "G", "B")
COHERENCE_PREFIX = "coherence."
COHERENCE_DIAGNOSTICS = ("l1_um", "l2_um", "angle", "anisotropy", "area_um2", "r_m", "Mxx", "Mxy", "Myy")
"""The BRIEF's per-pixel diagnostics, in file order (``coherence.weight`` follows them)."""
COHERENCE_WEIGHT = "coherence.weight"
RADIANCE_UNIT = "W·m⁻²·sr⁻¹·nm⁻¹"
"""Unit of the spectral bands and of R, G, B (band-averaged spectral radiance)."""
CHANNEL_UNITS: dict[str, str] = {
    **{
        COHERENCE_PREFIX + name: unit
        for name, unit in (
            ("l1_um", "µm"),
            ("l2_um", "µm"),
            ("angle", "rad"),
            ("anisotropy", "1"),
            ("area_um2", "µm²"),
            ("r_m", "m"),
            ("Mxx", "m⁻²"),
            ("Mxy", "m⁻²"),
            ("Myy", "m⁻²"),
            ("weight", "1"),
        )
    },
    "depth": "m",
}
"""Units of the diagnostic and geometry channels (dimensionless ones: ``1``)."""
LUMINANCE_VARIANCE = "Y"
"""``variance.exr``'s channel of the luminance mean's variance (beside one channel per band)."""

LAMBDA_REFERENCE_NM = 550.0
"""Diagnostic lengths are reported at this wavelength (BRIEF); they scale ∝ λ."""
K_REFERENCE_PER_M = 2.0 * math.pi / (LAMBDA_REFERENCE_NM * 1e-9)
"""Its wavenumber k (1/m)."""


def spectral_channel_name(center_nm: float) -> str:
    """``S0.<λ>nm`` for a band centre in nm (six decimals, comma separator)."""
    return SPECTRAL_PREFIX + f"{center_nm:.6f}".replace(".", ",") + "nm"


def is_spectral_channel(name: str) -> bool:
    return name.startswith(SPECTRAL_PREFIX) and name.endswith("nm")


def spectral_channel_wavelength_nm(name: str) -> float:
    """The band centre (nm) of a spectral channel name; ValueError names anything else."""
    if not is_spectral_channel(name):
        raise InputError(f"name: {name!r} is not a spectral channel S0.<wavelength>nm")
    try:
        return float(name[len(SPECTRAL_PREFIX) : -2].replace(",", "."))
    except ValueError:
        raise InputError(f"name: {name!r} is not a spectral channel S0.<wavelength>nm") from None


def coherence_channel(diagnostic: str) -> str:
    """``coherence.<diagnostic>``."""
    return COHERENCE_PREFIX + diagnostic


@dataclass(frozen=True)
class BandLayout:
    """``band_count`` equal bands over [wavelength_min_nm, wavelength_max_nm] (nm)."""

    wavelength_min_nm: float
    wavelength_max_nm: float
    band_count: int

    @property
    def width_nm(self) -> float:
        return (self.wavelength_max_nm - self.wavelength_min_nm) / self.band_count

    @property
    def centers_nm(self) -> np.ndarray:
        return self.wavelength_min_nm + self.width_nm * (np.arange(self.band_count) + 0.5)

    @property
    def edges_nm(self) -> np.ndarray:
        return self.wavelength_min_nm + self.width_nm * np.arange(self.band_count + 1)

    def channel_names(self) -> list[str]:
        """The spectral EXR channel names of the bands, in band order."""
        return [spectral_channel_name(center) for center in self.centers_nm]
