"""Final images from merged per-pixel sums: spectral OpenEXR, variance EXR, preview PNG, summary JSON.

``image.exr`` follows Fichet, Pacanowski & Wilkie (JCGT 10(3), 2021): emissive channels ``S0.<λ>nm``
(band centres, six decimals, comma separator), attributes ``spectralLayoutVersion`` = ``1.0`` and
``emissiveUnits`` = ``W.m^-2.sr^-1``; ``R``, ``G``, ``B`` linear sRGB (CIE 1931 2°, D65 white, XYZ from
the bands, normalised so that a unit equal-energy spectrum has Y = 1); the BRIEF's ``coherence.*``
diagnostics; ``depth`` (m), ``normal.X/Y/Z`` (world) and ``albedo.R/G/B`` of the first hit.
``variance.exr`` holds the variance of each band's pixel mean (σ²/N, from the per-sample second moments)
for noise-aware regression tests. Writes are atomic. Names and channels: ``hgcore.artifacts.layout``.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.artifacts.exr import write_exr
from hgcore.artifacts.layout import (
    COHERENCE_DIAGNOSTICS,
    COHERENCE_WEIGHT,
    IMAGE_EXR,
    K_REFERENCE_PER_M,
    LAMBDA_REFERENCE_NM,
    LUMINANCE_VARIANCE,
    PREVIEW_PNG,
    RGB_CHANNELS,
    SPECTRAL_ATTRIBUTES,
    SUMMARY_JSON,
    VARIANCE_EXR,
    BandLayout,
    coherence_channel,
)
from hgcore.artifacts.pixel_sums import PixelSums
from hgcore.colour import band_edges_xyz_weights, xyz_to_linear_srgb, y_bar_integral_nm
from hgcore.files import atomic_write_bytes
from hgcore.imaging import auto_exposure_ev, display_rgb8
from hgcore.optics.coherence import diagnostics_components


def images_from_sums(sums: PixelSums, bands: BandLayout) -> dict[str, np.ndarray]:
    """Per-pixel means and diagnostics (float32 arrays of shape (H, W) or (H, W, B))."""
    count = float(sums.sample_count)
    band_mean = sums.bands / count
    band_variance = np.maximum(sums.bands_sq / count - band_mean**2, 0.0) / count
    # Normalised so that a unit equal-energy spectrum has Y = 1 (Mitsuba's film convention).
    xyz = band_mean @ band_edges_xyz_weights(bands.edges_nm) / y_bar_integral_nm()
    rgb = xyz_to_linear_srgb(xyz)
    values = sums.values
    weight = values["diag_w"]
    covered = weight > 0
    safe = np.where(covered, weight, 1.0)
    m_xx, m_xy, m_yy = (
        np.where(covered, values[key] / safe, 0.0) for key in ("diag_mxx", "diag_mxy", "diag_myy")
    )
    r_mean = np.where(covered, values["diag_r"] / safe, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        # (k/r)² Σ with r = k gives M itself: the diagnostics are computed from M directly.
        diag = diagnostics_components(m_xx, m_xy, m_yy, K_REFERENCE_PER_M, LAMBDA_REFERENCE_NM * 1e-9)
    angle = 0.5 * np.arctan2(values["diag_s2"], values["diag_c2"])
    coherence = {
        "l1_um": diag.l1_um,
        "l2_um": diag.l2_um,
        "angle": angle,
        "anisotropy": diag.anisotropy,
        "area_um2": diag.area_um2,
        "r_m": r_mean,
        "Mxx": m_xx,
        "Mxy": m_xy,
        "Myy": m_yy,
    }
    coherence = {
        key: np.where(covered, np.nan_to_num(value, nan=0.0, posinf=0.0), 0.0)
        for key, value in coherence.items()
    }
    albedo_xyz = np.stack([values[f"albedo_{c}"] for c in "xyz"], axis=-1) / count
    return {
        "bands": band_mean.astype(np.float32),
        "band_variance": band_variance.astype(np.float32),
        "rgb": rgb.astype(np.float32),
        "depth": (values["depth"] / count).astype(np.float32),
        "normal": (np.stack([values[f"normal_{c}"] for c in "xyz"], axis=-1) / count).astype(np.float32),
        "albedo": xyz_to_linear_srgb(albedo_xyz).astype(np.float32),
        "luminance_variance": (
            np.maximum(values["luminance_sq"] / count - (values["luminance"] / count) ** 2, 0.0) / count
        ).astype(np.float32),
        **{coherence_channel(key): value.astype(np.float32) for key, value in coherence.items()},
        COHERENCE_WEIGHT: (weight / count).astype(np.float32),
    }


def image_channels(images: dict[str, np.ndarray], bands: BandLayout) -> list[tuple[str, np.ndarray]]:
    """The (name, (H, W) array) channels of ``image.exr`` in file order."""
    channels = [(name, images["rgb"][..., i]) for i, name in enumerate(RGB_CHANNELS)]
    channels += [(name, images["bands"][..., b]) for b, name in enumerate(bands.channel_names())]
    channels += [(coherence_channel(key), images[coherence_channel(key)]) for key in COHERENCE_DIAGNOSTICS]
    channels += [(COHERENCE_WEIGHT, images[COHERENCE_WEIGHT])]
    channels += [("depth", images["depth"])]
    channels += [(f"normal.{axis}", images["normal"][..., i]) for i, axis in enumerate("XYZ")]
    channels += [(f"albedo.{c}", images["albedo"][..., i]) for i, c in enumerate("RGB")]
    return channels


def channels_from_sums(sums: PixelSums, bands: BandLayout) -> dict[str, np.ndarray]:
    """``image.exr``'s channels (name → float32 (H, W) array) for sums, without writing a file: a running
    job's preview (the viewer, tev)."""
    images = images_from_sums(sums, bands)
    return {
        name: np.ascontiguousarray(values, dtype=np.float32) for name, values in image_channels(images, bands)
    }


def write_images(images: dict[str, np.ndarray], bands: BandLayout, out_dir: Path) -> list[str]:
    """image.exr, variance.exr and preview.png into ``out_dir``; returns the file names."""
    write_exr(out_dir / IMAGE_EXR, image_channels(images, bands), SPECTRAL_ATTRIBUTES)
    variance = [(name, images["band_variance"][..., b]) for b, name in enumerate(bands.channel_names())]
    variance.append((LUMINANCE_VARIANCE, images["luminance_variance"]))
    write_exr(out_dir / VARIANCE_EXR, variance, SPECTRAL_ATTRIBUTES)
    atomic_write_bytes(out_dir / PREVIEW_PNG, preview_png(images["rgb"]))
    return [IMAGE_EXR, VARIANCE_EXR, PREVIEW_PNG]


def preview_png(rgb: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(display_rgb8(rgb, auto_exposure_ev(rgb))).save(buffer, format="PNG")
    return buffer.getvalue()


def coherence_statistics(images: dict[str, np.ndarray]) -> dict[str, Any]:
    """Mean and percentiles of ℓ₁, ℓ₂, anisotropy and area over pixels with diagnostics."""
    covered = images[COHERENCE_WEIGHT] > 0
    stats: dict[str, Any] = {"covered_pixels": int(covered.sum())}
    for key in ("l1_um", "l2_um", "anisotropy", "area_um2", "r_m"):
        values = images[coherence_channel(key)][covered]
        if values.size == 0:
            stats[key] = None
            continue
        stats[key] = {
            "mean": float(values.mean()),
            "p5": float(np.percentile(values, 5)),
            "p50": float(np.percentile(values, 50)),
            "p95": float(np.percentile(values, 95)),
        }
    return stats


def write_summary(out_dir: Path, summary: dict[str, Any]) -> None:
    atomic_write_bytes(out_dir / SUMMARY_JSON, json.dumps(summary, indent=2, sort_keys=True).encode())
