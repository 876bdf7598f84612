"""Final images from merged per-pixel sums: spectral OpenEXR, variance EXR, preview PNG, summary JSON.

``image.exr`` follows Fichet, Pacanowski & Wilkie (JCGT 10(3), 2021): emissive channels ``S0.<λ>nm``
(band centres, six decimals, comma separator), attributes ``spectralLayoutVersion`` = ``1.0`` and
``emissiveUnits`` = ``W.m^-2.sr^-1``; ``R``, ``G``, ``B`` linear sRGB (CIE 1931 2°, D65 white, XYZ from
the bands, normalised so that a unit equal-energy spectrum has Y = 1); the BRIEF's ``coherence.*``
diagnostics; ``depth`` (m), ``normal.X/Y/Z`` (world) and ``albedo.R/G/B`` of the first hit.
``variance.exr`` holds the variance of each band's pixel mean (σ̂²/N, from the per-sample second moments
with the 1/N sample variance) and ``Y``, that of the pixel's luminance in image.exr's units (the
per-sample Y of the band values with the same weights), for noise-aware regression tests and error bars.
Writes are atomic. Names and channels: ``hgcore.artifacts.layout``.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.artifacts.exr import ExrScanlineWriter, exr_scanline_writer
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
from hgcore.artifacts.pixel_sums import PixelSums, variance_of_mean
from hgcore.colour import image_xyz_weights, xyz_to_linear_srgb
from hgcore.files import atomic_write_bytes
from hgcore.imaging import display_rgb8, preview_exposure_ev
from hgcore.optics.coherence import (
    diagnostics_components,
    positive_semidefinite_components,
    principal_axes_components,
)
from hgcore.optics.frames import transverse_frame_components


@dataclass
class SecondarySource:
    """The VCZ estimate of the light a pixel receives from secondary sources (per-pixel arrays)."""

    weight: np.ndarray  # luminance-weighted sample weight that enters the pixel's diagnostics
    weighted_r: np.ndarray  # that weight times the distance to the source (m)
    m_per_m2: tuple[np.ndarray, np.ndarray, np.ndarray]  # M = k²·Cov(ω⊥) at 550 nm (xx, xy, yy)
    cos_2psi: np.ndarray  # doubled screen angle of the ℓ₁ axis
    sin_2psi: np.ndarray


def secondary_source_m(values: dict[str, np.ndarray]) -> SecondarySource:
    """M of the light from non-specular surfaces by van Cittert–Zernike (docs/physics.md §7).

    An incoherent source of radiance L(ω) seen from the receiver has μ(ξ) = ∫L e^{ik ω⊥·ξ}dω / ∫L dω
    (far field), whose curvature at ξ = 0 gives M = k²·Cov(ω⊥): the covariance of the arrival directions
    weighted by the light they bring. The pixel's paths sample those directions with exactly that weight
    (their luminance contribution), so the weighted sample covariance of their unit arrival directions d,
    with the effective-sample-count correction W²/(W² − Σw²) (unbiased for weighted samples), projected on
    the plane ⟂ the mean direction estimates it. Pixels with fewer than three effective samples have no
    estimate and leave this part out (two directions span a line only: a rank-one covariance whose ℓ₁ is
    unbounded). Directions are in camera coordinates (right, up, forward), so the
    transverse x axis is the camera's right vector projected, as for the other paths (``frames``).
    """
    weight = values["vcz_w"]
    weight_sq = values["vcz_w2"]
    with np.errstate(divide="ignore", invalid="ignore"):
        effective = np.where(weight_sq > 0, weight * weight / weight_sq, 0.0)
    usable = effective >= 3.0
    safe = np.where(usable, weight, 1.0)
    mean = np.stack([values[f"vcz_d{axis}"] / safe for axis in "xyz"], axis=-1)
    second = np.empty((*weight.shape, 3, 3))
    for i, a in enumerate("xyz"):
        for j, b in enumerate("xyz"):
            key = f"vcz_d{a}{b}" if i <= j else f"vcz_d{b}{a}"
            second[..., i, j] = values[key] / safe
    bessel = np.where(usable, effective / np.maximum(effective - 1.0, 1.0), 0.0)
    covariance = (second - mean[..., :, None] * mean[..., None, :]) * bessel[..., None, None]
    norm = np.linalg.norm(mean, axis=-1, keepdims=True)
    propagation = -mean / np.where(norm > 0, norm, 1.0)  # light travels from the source to the receiver
    right = np.broadcast_to(np.array([1.0, 0.0, 0.0]), propagation.shape)
    x_axis, y_axis = transverse_frame_components(
        tuple(propagation[..., i] for i in range(3)), tuple(right[..., i] for i in range(3))
    )
    x_axis, y_axis = np.stack(x_axis, axis=-1), np.stack(y_axis, axis=-1)

    def project(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("...i,...ij,...j->...", u, covariance, v)

    k2 = K_REFERENCE_PER_M**2
    m = (k2 * project(x_axis, x_axis), k2 * project(x_axis, y_axis), k2 * project(y_axis, y_axis))
    # second − mean² cancels when the arrival directions agree (a small secondary source: k² ≈ 1.3e14/m²
    # turns a float32 rounding of 1e-9 into |M| ≈ 1e5): the estimate is projected on the PSD matrices.
    with np.errstate(divide="ignore", invalid="ignore"):
        m = positive_semidefinite_components(*m)
    m = tuple(np.where(usable, np.nan_to_num(component), 0.0) for component in m)
    # ℓ₁ runs along the eigenvector of M's smaller eigenvalue: e₂ = (−sin φ, cos φ) of principal_axes.
    with np.errstate(divide="ignore", invalid="ignore"):  # M = 0 where there is no estimate
        _, _, cos_phi, sin_phi = principal_axes_components(*m)
    axis = -sin_phi[..., None] * x_axis + cos_phi[..., None] * y_axis
    screen_x, screen_y = axis[..., 0], axis[..., 1]
    norm2 = np.maximum(screen_x**2 + screen_y**2, 1e-20)
    isotropic = np.abs(m[0] - m[2]) + 2 * np.abs(m[1]) <= 1e-6 * (m[0] + m[2])
    return SecondarySource(
        weight=np.where(usable, weight, 0.0),
        weighted_r=np.where(usable, values["vcz_r"], 0.0),
        m_per_m2=m,
        cos_2psi=np.where(usable & ~isotropic, (screen_x**2 - screen_y**2) / norm2, 0.0),
        sin_2psi=np.where(usable & ~isotropic, 2 * screen_x * screen_y / norm2, 0.0),
    )


def images_from_sums(sums: PixelSums, bands: BandLayout) -> dict[str, np.ndarray]:
    """Per-pixel means and diagnostics (float32 arrays of shape (H, W) or (H, W, B))."""
    count = float(sums.sample_count)
    band_mean = sums.bands / count
    band_variance = variance_of_mean(sums.bands, sums.bands_sq, sums.sample_count)
    xyz = band_mean @ image_xyz_weights(bands.edges_nm)
    rgb = xyz_to_linear_srgb(xyz)
    values = sums.values
    secondary = secondary_source_m(values)
    weight = values["diag_w"] + secondary.weight
    covered = weight > 0
    safe = np.where(covered, weight, 1.0)
    m_xx, m_xy, m_yy = (
        np.where(covered, (values[key] + secondary.weight * m) / safe, 0.0)
        for key, m in zip(("diag_mxx", "diag_mxy", "diag_myy"), secondary.m_per_m2, strict=True)
    )
    # A weighted mean of PSD matrices is PSD; float32 sums of nearly rank-one ones can round past it.
    with np.errstate(divide="ignore", invalid="ignore"):
        m_xx, m_xy, m_yy = (np.nan_to_num(m) for m in positive_semidefinite_components(m_xx, m_xy, m_yy))
    r_mean = np.where(covered, (values["diag_r"] + secondary.weighted_r) / safe, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        # (k/r)² Σ with r = k gives M itself: the diagnostics are computed from M directly.
        diag = diagnostics_components(m_xx, m_xy, m_yy, K_REFERENCE_PER_M, LAMBDA_REFERENCE_NM * 1e-9)
    angle = 0.5 * np.arctan2(
        values["diag_s2"] + secondary.weight * secondary.sin_2psi,
        values["diag_c2"] + secondary.weight * secondary.cos_2psi,
    )
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
        "luminance_variance": variance_of_mean(
            values["luminance"], values["luminance_sq"], sums.sample_count
        ).astype(np.float32),
        **{coherence_channel(key): value.astype(np.float32) for key, value in coherence.items()},
        COHERENCE_WEIGHT: (weight / count).astype(np.float32),
    }


def image_channel_layout(bands: BandLayout) -> list[tuple[str, str, int | None]]:
    """``image.exr``'s channels in file order: (channel name, key in ``images_from_sums``, index along its
    last axis or None)."""
    layout: list[tuple[str, str, int | None]] = [(name, "rgb", i) for i, name in enumerate(RGB_CHANNELS)]
    layout += [(name, "bands", b) for b, name in enumerate(bands.channel_names())]
    layout += [(coherence_channel(key), coherence_channel(key), None) for key in COHERENCE_DIAGNOSTICS]
    layout += [(COHERENCE_WEIGHT, COHERENCE_WEIGHT, None), ("depth", "depth", None)]
    layout += [(f"normal.{axis}", "normal", i) for i, axis in enumerate("XYZ")]
    layout += [(f"albedo.{c}", "albedo", i) for i, c in enumerate("RGB")]
    return layout


def image_channels(images: dict[str, np.ndarray], bands: BandLayout) -> list[tuple[str, np.ndarray]]:
    """The (name, (H, W) array) channels of ``image.exr`` in file order."""
    return [
        (name, images[key] if index is None else images[key][..., index])
        for name, key, index in image_channel_layout(bands)
    ]


def channels_from_sums(sums: PixelSums, bands: BandLayout) -> dict[str, np.ndarray]:
    """``image.exr``'s channels (name → float32 (H, W) array) for sums, without writing a file: a running
    job's preview (the viewer, tev)."""
    images = images_from_sums(sums, bands)
    return {
        name: np.ascontiguousarray(values, dtype=np.float32) for name, values in image_channels(images, bands)
    }


def variance_channels(images: dict[str, np.ndarray], bands: BandLayout) -> list[tuple[str, np.ndarray]]:
    """The (name, (H, W) array) channels of ``variance.exr`` in file order."""
    channels = [(name, images["band_variance"][..., b]) for b, name in enumerate(bands.channel_names())]
    return [*channels, (LUMINANCE_VARIANCE, images["luminance_variance"])]


STATISTIC_KEYS = ("l1_um", "l2_um", "anisotropy", "area_um2", "r_m")


class ImageSetWriter:
    """Writes a render's images from its sums row band by row band (see ``image_set_writer``): each band's
    means and diagnostics are per-pixel functions of that band's sums, so building them band by band
    gives the whole image's pixels; only the preview's RGB and the covered pixels' statistic values are
    kept for the whole image (3 + ≤ 5 float32 per pixel)."""

    def __init__(
        self,
        bands: BandLayout,
        width: int,
        height: int,
        image: ExrScanlineWriter,
        variance: ExrScanlineWriter,
    ) -> None:
        self.bands, self.width, self.height = bands, width, height
        self._image, self._variance = image, variance
        self.rgb = np.zeros((height, width, 3), dtype=np.float32)
        self._statistics: dict[str, list[np.ndarray]] = {key: [] for key in STATISTIC_KEYS}
        self._covered = 0
        self.rows_written = 0

    def write_rows(self, sums: PixelSums) -> None:
        """The images of the next rows (their sums), appended to image.exr and variance.exr."""
        y0, y1 = self.rows_written, self.rows_written + sums.rows
        images = images_from_sums(sums, self.bands)
        self._image.write_rows(y0, [data for _, data in image_channels(images, self.bands)])
        self._variance.write_rows(y0, [data for _, data in variance_channels(images, self.bands)])
        self.rgb[y0:y1] = images["rgb"]
        covered = images[COHERENCE_WEIGHT] > 0
        self._covered += int(covered.sum())
        for key in STATISTIC_KEYS:
            self._statistics[key].append(images[coherence_channel(key)][covered])
        self.rows_written = y1

    def coherence_statistics(self) -> dict[str, Any]:
        """Mean and percentiles of ℓ₁, ℓ₂, anisotropy, area and r over pixels with diagnostics."""
        stats: dict[str, Any] = {"covered_pixels": self._covered}
        for key in STATISTIC_KEYS:
            values = np.concatenate(self._statistics[key])
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


@contextmanager
def image_set_writer(out_dir: Path, bands: BandLayout, width: int, height: int) -> Iterator[ImageSetWriter]:
    """An ``ImageSetWriter`` for image.exr and variance.exr in ``out_dir``; preview.png is written when
    the block ends (its exposure needs the whole image). Files: ``IMAGE_FILES``."""
    out_dir = Path(out_dir)
    image_names = [name for name, _, _ in image_channel_layout(bands)]
    variance_names = [*bands.channel_names(), LUMINANCE_VARIANCE]
    with (
        exr_scanline_writer(out_dir / IMAGE_EXR, width, height, image_names, SPECTRAL_ATTRIBUTES) as image,
        exr_scanline_writer(
            out_dir / VARIANCE_EXR, width, height, variance_names, SPECTRAL_ATTRIBUTES
        ) as variance,
    ):
        writer = ImageSetWriter(bands, width, height, image, variance)
        yield writer
    atomic_write_bytes(out_dir / PREVIEW_PNG, preview_png(writer.rgb))


IMAGE_FILES = [IMAGE_EXR, VARIANCE_EXR, PREVIEW_PNG]


def preview_png(rgb: np.ndarray) -> bytes:
    """8-bit sRGB PNG at :func:`hgcore.imaging.preview_exposure_ev` (highlight colours unclipped), ``clamp``
    tone map. The viewer opens at ``auto_exposure_ev`` instead (luminance p99, docs/viewer.md), which is
    brighter on scenes whose highlights are saturated colours."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(display_rgb8(rgb, preview_exposure_ev(rgb))).save(buffer, format="PNG")
    return buffer.getvalue()


def write_summary(out_dir: Path, summary: dict[str, Any]) -> None:
    atomic_write_bytes(out_dir / SUMMARY_JSON, json.dumps(summary, indent=2, sort_keys=True).encode())
