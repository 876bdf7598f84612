"""A job's render outputs as arrays: spectral bands, their per-pixel variance and the coherence diagnostics.

``image.exr`` holds the bands ``S0.<λ>nm`` (Fichet et al. 2021; radiance in W·m⁻²·sr⁻¹·nm⁻¹, λ with a comma
decimal separator) and ``coherence.<name>``; ``variance.exr`` holds, under the same band names, the variance
of each pixel's Monte Carlo mean (σ̂²/N, same units squared); ``summary.json`` gives N (``spp``). Read
with OpenImageIO; NumPy only (the service imports this module, so no Mitsuba).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hgcore.artifacts.exr import ArtifactFormatError, read_exr
from hgcore.artifacts.layout import COHERENCE_WEIGHT, IMAGE_EXR, SUMMARY_JSON, VARIANCE_EXR, coherence_channel

COHERENCE_METRIC_CHANNELS: tuple[str, ...] = ("l1_um", "l2_um", "anisotropy")
"""Coherence diagnostics compared by the drift metric (``coherence.<name>``)."""


@dataclass(frozen=True)
class RenderOutputs:
    """One render: band radiance and variance of shape (H, W, B), band centres (B,) in nm, and the
    coherence diagnostics (H, W) keyed by name (``l1_um``, ``l2_um``, ``anisotropy``, ``weight``).

    ``band_variance`` is unbiased: ``variance.exr`` stores σ̂²/N with the 1/N sample variance σ̂², whose
    expectation is σ²(N−1)/N, so it is scaled by N/(N−1) with N = the samples per pixel of
    ``summary.json`` (at 4-8 spp the uncorrected value would understate the noise by 12-25 %)."""

    band_centers_nm: np.ndarray
    bands: np.ndarray
    band_variance: np.ndarray
    coherence: dict[str, np.ndarray]
    spp: int


def load_render_outputs(directory: Path) -> RenderOutputs:
    """``image.exr``, ``variance.exr`` and ``summary.json`` (for the spp) of one job from ``directory``."""
    directory = Path(directory)
    spp = int(json.loads((directory / SUMMARY_JSON).read_text())["spp"])
    if spp < 2:
        raise ArtifactFormatError(f"{SUMMARY_JSON}: rendered with {spp} spp; noise estimates need >= 2")
    image = read_exr(directory / IMAGE_EXR)
    variance = read_exr(directory / VARIANCE_EXR)
    bands = image.spectral_channels()
    if len(bands) < 2:
        raise ArtifactFormatError(f"{IMAGE_EXR}: has fewer than 2 spectral S0.<λ>nm channels")
    variance.require([name for _, name in bands], VARIANCE_EXR)
    coherence = {
        name: image.channels[coherence_channel(name)].astype(np.float64)
        for name in COHERENCE_METRIC_CHANNELS
        if coherence_channel(name) in image.channels
    }
    if COHERENCE_WEIGHT in image.channels:
        coherence["weight"] = image.channels[COHERENCE_WEIGHT].astype(np.float64)
    return RenderOutputs(
        band_centers_nm=np.array([center for center, _ in bands]),
        bands=np.stack([image.channels[name] for _, name in bands], axis=-1).astype(np.float64),
        band_variance=np.stack([variance.channels[name] for _, name in bands], axis=-1).astype(np.float64)
        * (spp / (spp - 1)),
        coherence=coherence,
        spp=spp,
    )
