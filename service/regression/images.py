"""A job's render outputs as arrays: spectral bands, their per-pixel variance and the coherence diagnostics.

``image.exr`` holds the bands ``S0.<λ>nm`` (Fichet et al. 2021; radiance in W·m⁻²·sr⁻¹·nm⁻¹, λ with a comma
decimal separator) and ``coherence.<name>``; ``variance.exr`` holds, under the same band names, the variance
of each pixel's Monte Carlo mean (σ̂²/N, same units squared); ``summary.json`` gives N (``spp``). Read
with OpenImageIO; NumPy only (the service imports this module, so no Mitsuba).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

_BAND_CHANNEL = re.compile(r"^S0\.(\d+),(\d+)nm$")
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


def read_exr_channels(path: Path) -> dict[str, np.ndarray]:
    """Every channel of an EXR file as float64 (H, W) arrays keyed by channel name."""
    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise ValueError(f"path: cannot open {path} as an image: {oiio.geterror()}")
    try:
        spec = image.spec()
        pixels = image.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    finally:
        image.close()
    if pixels is None:
        raise ValueError(f"path: cannot read the pixels of {path}")
    pixels = np.asarray(pixels, dtype=np.float64).reshape(spec.height, spec.width, spec.nchannels)
    return {name: pixels[..., index] for index, name in enumerate(spec.channelnames)}


def band_channels(channels: dict[str, np.ndarray]) -> list[tuple[float, str]]:
    """(centre in nm, channel name) of the spectral ``S0.<λ>nm`` channels, by wavelength."""
    found = []
    for name in channels:
        match = _BAND_CHANNEL.match(name)
        if match:
            found.append((float(f"{match.group(1)}.{match.group(2)}"), name))
    return sorted(found)


def load_render_outputs(directory: Path) -> RenderOutputs:
    """``image.exr``, ``variance.exr`` and ``summary.json`` (for the spp) of one job from ``directory``."""
    directory = Path(directory)
    spp = int(json.loads((directory / "summary.json").read_text())["spp"])
    if spp < 2:
        raise ValueError(f"directory: {directory} was rendered with {spp} spp; noise estimates need >= 2")
    image = read_exr_channels(directory / "image.exr")
    variance = read_exr_channels(directory / "variance.exr")
    bands = band_channels(image)
    if len(bands) < 2:
        raise ValueError(f"directory: {directory / 'image.exr'} has fewer than 2 spectral S0.<λ>nm channels")
    missing = [name for _, name in bands if name not in variance]
    if missing:
        raise ValueError(f"directory: {directory / 'variance.exr'} lacks the band channels {missing}")
    coherence = {
        name: image[f"coherence.{name}"]
        for name in (*COHERENCE_METRIC_CHANNELS, "weight")
        if f"coherence.{name}" in image
    }
    return RenderOutputs(
        band_centers_nm=np.array([center for center, _ in bands]),
        bands=np.stack([image[name] for _, name in bands], axis=-1),
        band_variance=np.stack([variance[name] for _, name in bands], axis=-1) * (spp / (spp - 1)),
        coherence=coherence,
        spp=spp,
    )
