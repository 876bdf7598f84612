"""Data the browser viewer needs, computed from a job's ``image.exr``: a layer catalogue, raw layer arrays,
pixel records, server-side display images, coherence-ellipse grids and two-job differences.

Each EXR is read once with OpenImageIO and its decoded channels are kept in an LRU cache bounded by a
number of images (:class:`DecodedImageCache`). NumPy and OpenImageIO only: the service never imports
Mitsuba or Dr.Jit.

Conventions. Pixel (x, y) counts from the top-left corner, x to the right and y down (EXR row order).
``coherence.angle`` is the screen-space orientation of the ℓ₁ axis in radians, measured from image +x
towards image +y *up* (counter-clockwise on screen). Lengths ℓ₁, ℓ₂ are 1/√e half-widths of
|μ(ξ)| = exp(−½ ξᵀMξ) at λ = 550 nm (BRIEF); M in m⁻². Band radiances are band-averaged spectral
radiances in W·m⁻²·sr⁻¹·nm⁻¹; ``R``, ``G``, ``B`` are linear sRGB of the same unit scale.

Downsampling (``step`` N): radiometric layers (bands, RGB) are averaged over N×N blocks (the same as
rendering with N×N larger pixels); every other layer (diagnostics, depth, normals, albedo) is sampled at
the top-left pixel of each block, because the mean of angles or of per-path lengths is not a diagnostic.
"""

from __future__ import annotations

import io
import math
import tempfile
import threading
import uuid
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from hgcore.artifacts.exr import ArtifactFormatError, read_exr, write_exr
from hgcore.artifacts.images import channels_from_sums
from hgcore.artifacts.keys import artifact_key, chunks_prefix
from hgcore.artifacts.layout import (
    CHANNEL_UNITS,
    CHUNK_PARTIAL_SUFFIX,
    COHERENCE_DIAGNOSTICS,
    COHERENCE_PREFIX,
    COHERENCE_WEIGHT,
    IMAGE_EXR,
    RADIANCE_UNIT,
    RGB_CHANNELS,
    BandLayout,
    coherence_channel,
    is_spectral_channel,
    spectral_channel_wavelength_nm,
)
from hgcore.artifacts.pixel_sums import PixelSums, read_partial
from hgcore.colour import XYZ_TO_LINEAR_SRGB, radiance_xyz
from hgcore.errors import InputError
from hgcore.image_metrics import PERCEPTUAL_METRICS, metric_exposure_ev, perceptual_map
from hgcore.imaging import REC709_LUMINANCE, auto_exposure_ev, display_rgb8
from hgcore.store.base import ArtifactNotFoundError, ArtifactStore

RGB_LAYER = "rgb"
COMPARE_MODES: tuple[str, ...] = ("abs", "rel", *PERCEPTUAL_METRICS)


def layer_kind(name: str) -> str:
    """``rgb``, ``band``, ``coherence`` or ``geometry`` (depth, normals, albedo)."""
    if name in (RGB_LAYER, "R", "G", "B"):
        return "rgb"
    if is_spectral_channel(name):
        return "band"
    if name.startswith(COHERENCE_PREFIX):
        return "coherence"
    return "geometry"


def layer_unit(name: str) -> str:
    kind = layer_kind(name)
    if kind in ("rgb", "band"):
        return RADIANCE_UNIT
    return CHANNEL_UNITS.get(name, "1")


@dataclass(frozen=True)
class LayerInfo:
    """One displayable layer: its statistics over finite pixels (diagnostics: over covered pixels)."""

    name: str
    kind: str
    unit: str
    wavelength_nm: float | None
    channels: int
    min: float | None
    max: float | None
    p01: float | None
    p99: float | None


@dataclass
class DecodedImage:
    """The channels of one ``image.exr`` as float32 (H, W) arrays, plus derived catalogues."""

    width: int
    height: int
    channels: dict[str, np.ndarray]
    band_names: list[str] = field(default_factory=list)
    wavelengths_nm: list[float] = field(default_factory=list)
    partial: bool = False  # merged from the chunks finished so far (the job is still running)
    spp: int | None = None  # samples per pixel of a partial (a running job's preview), else unknown
    _layers: list[LayerInfo] | None = None
    _exposure_ev: float | None = None

    @property
    def rgb(self) -> np.ndarray:
        """Linear sRGB, shape (H, W, 3)."""
        return np.stack([self.channels["R"], self.channels["G"], self.channels["B"]], axis=-1)

    @property
    def covered(self) -> np.ndarray:
        """Pixels that carry coherence diagnostics (``coherence.weight`` > 0)."""
        weight = self.channels.get(COHERENCE_WEIGHT)
        if weight is None:
            return np.zeros((self.height, self.width), dtype=bool)
        return weight > 0

    @property
    def bands(self) -> np.ndarray:
        """Band radiances, shape (H, W, B), by wavelength."""
        return np.stack([self.channels[name] for name in self.band_names], axis=-1)

    def exposure_ev(self) -> float:
        """The automatic exposure (``hgcore.image_metrics.metric_exposure_ev``; computed once): the
        viewer's and the compare view's default, and what a regression run uses for its colour metrics."""
        if self._exposure_ev is None:
            # One band has no colour (bands → XYZ needs two): then the RGB luminance rule, the same EV.
            self._exposure_ev = (
                metric_exposure_ev(self.bands, np.array(self.wavelengths_nm))
                if len(self.band_names) >= 2
                else auto_exposure_ev(self.rgb)
            )
        return self._exposure_ev

    def layer(self, name: str) -> np.ndarray:
        """(H, W) float32 for a channel name, (H, W, 3) for ``rgb``; ValueError names unknown layers."""
        if name == RGB_LAYER:
            return self.rgb
        if name not in self.channels:
            raise InputError(f"name: no layer {name!r} (see GET /v1/jobs/{{id}}/layers)")
        return self.channels[name]

    def layers(self) -> list[LayerInfo]:
        """Catalogue of the layers (computed once)."""
        if self._layers is None:
            covered = self.covered
            names = [RGB_LAYER, *self.band_names]
            names += [n for n in sorted(self.channels) if n.startswith(COHERENCE_PREFIX)]
            names += [n for n in sorted(self.channels) if layer_kind(n) == "geometry"]
            infos = []
            for name in names:
                values = self.layer(name)
                if layer_kind(name) == "coherence" and name != COHERENCE_WEIGHT:
                    values = values[covered]
                values = values[np.isfinite(values)]
                if values.size:
                    low, high = (float(v) for v in np.percentile(values, [1.0, 99.0]))
                    stats = (float(values.min()), float(values.max()), low, high)
                else:
                    stats = (None, None, None, None)
                wavelength = spectral_channel_wavelength_nm(name) if layer_kind(name) == "band" else None
                channel_count = 3 if name == RGB_LAYER else 1
                infos.append(
                    LayerInfo(name, layer_kind(name), layer_unit(name), wavelength, channel_count, *stats)
                )
            self._layers = infos
        return self._layers


def decode_exr(path: Path) -> DecodedImage:
    """Read every channel of an EXR (first subimage) as float32 (H, W) arrays."""
    image = read_exr(path)
    return _decoded(image.width, image.height, image.channels)


EXR_MAGIC = b"\x76\x2f\x31\x01"
"""The first four bytes of every OpenEXR file."""


def decode_uploaded_exr(data: bytes) -> DecodedImage:
    """A spectral EXR sent by the browser (drag and drop), validated: an OpenEXR file with at least one
    ``S0.<λ>nm`` band; linear sRGB ``R``, ``G``, ``B`` are computed from the bands when absent. ValueError
    ("file: ...") otherwise, which the API answers with 422."""
    if not data.startswith(EXR_MAGIC):
        raise InputError("file: not an OpenEXR file (its first bytes are not the EXR magic number)")
    with tempfile.TemporaryDirectory(prefix="hgrender-upload-") as directory:
        path = Path(directory) / "upload.exr"
        path.write_bytes(data)
        try:
            image = decode_exr(path)
        except ArtifactFormatError as error:
            raise InputError(f"file: cannot decode the EXR: {error}") from None
    if len(image.band_names) < 2:
        names = ", ".join(sorted(image.channels)[:8])
        raise InputError(
            "file: needs at least 2 spectral channels S0.<wavelength>nm (e.g. S0.550,000000nm); "
            f"the file has {names}"
        )
    if not all(c in image.channels for c in "RGB"):
        xyz = radiance_xyz(image.bands, np.array(image.wavelengths_nm))
        rgb = (xyz @ XYZ_TO_LINEAR_SRGB.T).astype(np.float32)
        image.channels.update({c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")})
    return image


class UploadedImages:
    """Images dropped into the viewer from the user's disk: decoded and kept in memory only (never
    written to the artifact store), at most ``max_images`` (least recently used dropped), each visible to
    its uploader only. Ids share the 32-hex form of job ids, so every viewer endpoint serves them."""

    def __init__(self, max_images: int = 4) -> None:
        if max_images < 1:
            raise InputError(f"max_images: must be at least 1, got {max_images}")
        self.max_images = max_images
        self._images: OrderedDict[str, tuple[str, DecodedImage]] = OrderedDict()
        self._lock = threading.Lock()

    def add(self, owner: str, image: DecodedImage) -> str:
        image_id = uuid.uuid4().hex
        with self._lock:
            self._images[image_id] = (owner, image)
            while len(self._images) > self.max_images:
                self._images.popitem(last=False)
        return image_id

    def get(self, image_id: str, can_see: Callable[[str], bool]) -> DecodedImage | None:
        """The image if it exists and ``can_see(owner)``; None otherwise (then it is not an upload)."""
        with self._lock:
            entry = self._images.get(image_id)
            if entry is None or not can_see(entry[0]):
                return None
            self._images.move_to_end(image_id)
            return entry[1]


def _decoded(
    width: int,
    height: int,
    channels: dict[str, np.ndarray],
    partial: bool = False,
    spp: int | None = None,
) -> DecodedImage:
    band_names = sorted((n for n in channels if is_spectral_channel(n)), key=spectral_channel_wavelength_nm)
    return DecodedImage(
        width=width,
        height=height,
        channels=channels,
        band_names=band_names,
        wavelengths_nm=[spectral_channel_wavelength_nm(n) for n in band_names],
        partial=partial,
        spp=spp,
    )


def merge_partials(paths: list[Path], film: dict[str, Any]) -> DecodedImage:
    """The image of the chunk partials finished so far (a running job's preview): the renderer's own
    merge of per-pixel sums (``hgcore.artifacts.images``), without writing anything."""
    total: PixelSums | None = None
    for path in paths:
        sums, _ = read_partial(path)
        total = sums if total is None else total.add(sums)
    if total is None:
        raise ArtifactNotFoundError("chunks")
    bands = BandLayout(film["wavelength_min_nm"], film["wavelength_max_nm"], film["bands"])
    channels = channels_from_sums(total, bands)
    height, width = channels[COHERENCE_WEIGHT].shape
    return _decoded(width, height, channels, partial=True, spp=total.sample_count)


class DecodedImageCache:
    """LRU cache of decoded ``image.exr`` files keyed by (job id, stored size); thread-safe.

    The size in the key makes a rewritten artifact (a re-run merge) a cache miss; at most
    ``max_images`` images are kept (a 1024² image with 16 bands is ≈ 120 MB of float32).
    """

    def __init__(self, store: ArtifactStore, max_images: int = 8) -> None:
        if max_images < 1:
            raise InputError(f"max_images: must be at least 1, got {max_images}")
        self.store = store
        self.max_images = max_images
        self._images: OrderedDict[tuple[str, int], DecodedImage] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, job_id: str) -> DecodedImage:
        """The job's decoded image; ArtifactNotFoundError while the job has none (not finished)."""
        key = artifact_key(job_id, IMAGE_EXR)
        listed = [info for info in self.store.list(key) if info.key == key]
        if not listed:
            raise ArtifactNotFoundError(IMAGE_EXR)
        cache_key = (job_id, listed[0].size_bytes)
        cached = self._cached(cache_key)
        if cached is not None:
            return cached
        with tempfile.TemporaryDirectory(prefix="hgrender-viewer-") as directory:
            path = Path(directory) / IMAGE_EXR
            self.store.get_file(key, path)
            return self._keep(cache_key, decode_exr(path))

    def get_partial(self, job_id: str, film: dict[str, Any], revision: int = 0) -> DecodedImage:
        """A running job's preview from its finished chunk partials; ArtifactNotFoundError when none.
        ``revision`` tells apart partials that a job replaces under the same key with the same size (a
        noise-target job's chunk 0 after each round: the caller passes its round count)."""
        prefix = chunks_prefix(job_id)
        listed = sorted(
            (info for info in self.store.list(prefix) if info.key.endswith(CHUNK_PARTIAL_SUFFIX)),
            key=lambda i: i.key,
        )
        if not listed:
            raise ArtifactNotFoundError("chunks")
        cache_key = (job_id, hash((revision, *((info.key, info.size_bytes) for info in listed))))
        cached = self._cached(cache_key)
        if cached is not None:
            return cached
        with tempfile.TemporaryDirectory(prefix="hgrender-viewer-") as directory:
            paths = []
            for index, info in enumerate(listed):
                path = Path(directory) / f"{index}{CHUNK_PARTIAL_SUFFIX}"
                self.store.get_file(info.key, path)
                paths.append(path)
            return self._keep(cache_key, merge_partials(paths, film))

    def _cached(self, cache_key: tuple[str, int]) -> DecodedImage | None:
        with self._lock:
            if cache_key not in self._images:
                return None
            self._images.move_to_end(cache_key)
            return self._images[cache_key]

    def _keep(self, cache_key: tuple[str, int], image: DecodedImage) -> DecodedImage:
        """Cache ``image`` as the most recent, dropping the least recently used beyond ``max_images``."""
        with self._lock:
            self._images[cache_key] = image
            self._images.move_to_end(cache_key)
            while len(self._images) > self.max_images:
                self._images.popitem(last=False)
        return image

    def __len__(self) -> int:
        return len(self._images)


# ---- views of one image ----------------------------------------------------------------------------------


def _check_step(step: int) -> None:
    if not 1 <= step <= 64:
        raise InputError(f"step: must be between 1 and 64, got {step}")


def downsample(values: np.ndarray, step: int, average: bool) -> np.ndarray:
    """Every ``step``-th pixel (``average``: the mean of each step×step block, partial edge blocks
    averaged over the pixels they have). Shape (ceil(H/step), ceil(W/step), ...)."""
    _check_step(step)
    if step == 1:
        return values
    if not average:
        return values[::step, ::step]
    height, width = values.shape[:2]
    rows, cols = math.ceil(height / step), math.ceil(width / step)
    row_starts, col_starts = np.arange(rows) * step, np.arange(cols) * step
    sums = np.add.reduceat(np.add.reduceat(values.astype(np.float64), row_starts, axis=0), col_starts, axis=1)
    counts = np.outer(np.minimum(step, height - row_starts), np.minimum(step, width - col_starts))
    counts = counts.reshape(rows, cols, *([1] * (values.ndim - 2)))
    return (sums / counts).astype(np.float32)


def layer_array(image: DecodedImage, name: str, step: int = 1) -> np.ndarray:
    """The layer ``name`` downsampled by ``step`` (float32, (h, w) or (h, w, 3) for ``rgb``)."""
    values = image.layer(name)
    return downsample(values, step, average=layer_kind(name) in ("rgb", "band"))


def encode_array(values: np.ndarray, dtype: Literal["f16", "f32"]) -> bytes:
    """Little-endian raw bytes, row-major, channels interleaved."""
    if dtype not in ("f16", "f32"):
        raise InputError(f"format: must be f16 or f32, got {dtype!r}")
    return np.ascontiguousarray(values, dtype="<f2" if dtype == "f16" else "<f4").tobytes()


def pixel_record(image: DecodedImage, x: int, y: int) -> dict[str, object]:
    """Everything known about pixel (x, y): spectrum, linear RGB, coherence values, depth/normal/albedo."""
    if not 0 <= x < image.width:
        raise InputError(f"x: must be in [0, {image.width - 1}], got {x}")
    if not 0 <= y < image.height:
        raise InputError(f"y: must be in [0, {image.height - 1}], got {y}")

    def value(name: str) -> float | None:
        channel = image.channels.get(name)
        if channel is None or not math.isfinite(float(channel[y, x])):
            return None
        return float(channel[y, x])

    covered = bool(image.covered[y, x])
    coherence = {name: value(coherence_channel(name)) if covered else None for name in COHERENCE_DIAGNOSTICS}
    return {
        "x": x,
        "y": y,
        "wavelengths_nm": image.wavelengths_nm,
        "spectrum": [value(name) for name in image.band_names],
        "spectrum_unit": RADIANCE_UNIT,
        "rgb": [value(c) for c in RGB_CHANNELS],
        "coherence_covered": covered,
        "coherence": coherence,
        "coherence_weight": value(COHERENCE_WEIGHT),
        "depth_m": value("depth"),
        "normal": [value(f"normal.{a}") for a in "XYZ"],
        "albedo": [value(f"albedo.{c}") for c in "RGB"],
    }


def display_png(image: DecodedImage, exposure_ev: float, operator: str) -> bytes:
    """The sRGB image as the viewer shows it (``hgcore.imaging.display_rgb8``), PNG-encoded."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(display_rgb8(image.rgb, exposure_ev, operator)).save(buffer, format="PNG")
    return buffer.getvalue()


def diagnostics_exr(image: DecodedImage) -> bytes:
    """The ``coherence.*`` channels (ℓ₁, ℓ₂ in µm at 550 nm, angle, anisotropy, area, r, M, weight) as a
    float32 OpenEXR file, channel names as in ``image.exr``; ValueError when the image has none."""
    names = sorted(n for n in image.channels if n.startswith(COHERENCE_PREFIX))
    if not names:
        raise InputError("name: this image has no coherence diagnostics")
    with tempfile.TemporaryDirectory(prefix="hgrender-diagnostics-") as directory:
        path = Path(directory) / "diagnostics.exr"
        write_exr(path, [(name, image.channels[name]) for name in names], {})
        return path.read_bytes()


def ellipse_grid(image: DecodedImage, spacing_px: int) -> list[dict[str, float]]:
    """Coherence ellipses on a grid: one per ``spacing_px`` cell that has diagnostics at its centre pixel
    (x = y = spacing/2 + i·spacing, rounded down), with that pixel's ℓ₁, ℓ₂ (µm), angle (rad) and area
    (µm²). The ellipse's ℓ₁ axis points along (cos angle, sin angle) with image +y up."""
    if not 2 <= spacing_px <= 4096:
        raise InputError(f"spacing: must be between 2 and 4096 pixels, got {spacing_px}")
    covered = image.covered
    grid = []
    for y in range(spacing_px // 2, image.height, spacing_px):
        for x in range(spacing_px // 2, image.width, spacing_px):
            if not covered[y, x]:
                continue
            values = {
                name: float(image.channels[coherence_channel(name)][y, x])
                for name in ("l1_um", "l2_um", "angle", "area_um2")
            }
            if all(math.isfinite(v) for v in values.values()):
                grid.append({"x": x, "y": y, **values})
    return grid


# ---- comparing two images --------------------------------------------------------------------------------


def difference_map(
    reference: DecodedImage,
    sample: DecodedImage,
    mode: str,
    exposure_ev: float | None = None,
) -> np.ndarray:
    """Per-pixel difference of two same-sized images, float32 (H, W).

    * ``abs``: mean over R, G, B of |sample − reference| (linear sRGB radiance units);
    * ``rel``: mean over R, G, B of |sample − reference| / max(|reference|, ε), ε = 1 % of the
      reference's mean luminance (keeps black pixels from dividing by zero);
    * ``de2000``, ``flip``: CIEDE2000 ΔE₀₀ or ꟻLIP of the two spectral images at ``exposure_ev``
      (default: the reference's automatic exposure), by ``hgcore.image_metrics`` as regression runs do.
    """
    if (reference.width, reference.height) != (sample.width, sample.height):
        raise InputError(
            f"b: image is {sample.width}x{sample.height}, a is {reference.width}x{reference.height};"
            " compare needs equal sizes"
        )
    rgb_a, rgb_b = reference.rgb.astype(np.float64), sample.rgb.astype(np.float64)
    if mode == "abs":
        result = np.mean(np.abs(rgb_b - rgb_a), axis=-1)
    elif mode == "rel":
        floor = max(0.01 * float(np.mean(rgb_a @ REC709_LUMINANCE)), np.finfo(np.float32).tiny)
        result = np.mean(np.abs(rgb_b - rgb_a) / np.maximum(np.abs(rgb_a), floor), axis=-1)
    elif mode in PERCEPTUAL_METRICS:
        if reference.wavelengths_nm != sample.wavelengths_nm:
            raise InputError("b: its bands differ from a's; compare needs the same spectral layout")
        if len(reference.band_names) < 2:
            raise InputError(f"mode: {mode} needs at least 2 spectral bands (colour); a has one")
        ev = reference.exposure_ev() if exposure_ev is None else exposure_ev
        bands = np.array(reference.wavelengths_nm)
        result = perceptual_map(mode, reference.bands.astype(np.float64), sample.bands, bands, ev)
    else:
        raise InputError(f"mode: must be one of {', '.join(COMPARE_MODES)}, got {mode!r}")
    return result.astype(np.float32)
