"""Image textures in the kernels: one flat texel table, one layout row per binding, wrapped bilinear lookups.

A *binding* is one image as one material parameter reads it (``schemas.scene.ImageTexture``). Everything
that depends only on the binding happens once on the host: decoding (OpenImageIO, float32), the sRGB
transfer curve, the channel, ``scale``/``offset`` into the parameter's units, the clip to its range, and,
for a colour, the spectral upsampling (Jakob & Hanika 2019, ``hgcore.optics.rgb_upsampling``: three
coefficients per texel, fitted so that the texel's spectrum lit by D65 has the texel's linear sRGB colour).
The kernels then gather texels:

* texture coordinates (u, v) from the hit (origin at the image's bottom-left, v up: ``schemas.scene``),
  mapped by the binding's affine ``uv_transform``; pixel coordinates x = u·W, y = (1 − v)·H;
* ``bilinear``: the four texel centres around (x − ½, y − ½) with weights (1 − f)(1 − g) …;
  ``nearest``: the texel (⌊x⌋, ⌊y⌋) with weight 1;
* each texel index wrapped per axis (``repeat``, ``clamp``, ``mirror``; ``black``: weight 0 outside);
* a scalar is Σ w_k t_k (in the parameter's units, metres for lengths); a colour is Σ w_k S_{c_k}(λ_j) at
  the path's wavelengths — the texels' *spectra* are filtered, so the filtered reflectance is exactly the
  filter of the texels' reflectances (and its colour the filter of their colours).

Tables: ``texels`` (float32: 1 value or 4 = 3 coefficients + padding per texel, so that a texel is one
packet gather), ``layout`` (UInt32, 4 per binding: its first texel in units of its texels, width, flags =
wrap u | wrap v << 2 | bilinear << 4, height: one packet gather) and ``uv_affine`` (float32, 8 per binding:
u' = a u + b v + c, v' = d u + e v + f, padded; read only where some binding has a ``uv_transform``).
Bindings are numbered from 0; a material's table stores binding + 1 (0: no texture).

Wrapping costs no division: each axis's coordinate is first folded into [0, 1] (repeat: t − ⌊t⌋; mirror:
the fold of t − 2⌊t/2⌋; clamp and black keep t), the texel pair (i, i + 1) around it then lies in
[−1, size], and the neighbours across the seam (repeat) or edge (mirror, clamp: the edge texel; black: weight
0) are fixed by selects. (A division per wrap cost 13 % of a textured Cornell box; measured.)

No mipmaps: a texture minified on screen aliases within a pixel and is averaged by the pixel's samples
(as Mitsuba's ``bitmap`` without mipmapping).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.rgb_upsampling import CoefficientTable, fit_coefficients, sigmoid_polynomial
from schemas.scene import ImageTexture
from schemas.textures import ImageHeader

WRAP_MODES = {"repeat": 0, "clamp": 1, "mirror": 2, "black": 3}
FILTERS = {"nearest": 0, "bilinear": 1}
LAYOUT_STRIDE = 4
AFFINE_STRIDE = 8
COLOUR_COMPONENTS = 4  # three coefficients and a pad: one 4-wide packet gather per texel
CHANNELS = {"r": 0, "g": 1, "b": 2, "a": 3}


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve inverted (IEC 61966-2-1): encoded values in [0, 1] → linear."""
    values = np.asarray(encoded, dtype=np.float64)
    return np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4)


def decode_image(path: Path, header: ImageHeader, colour_space: str) -> np.ndarray:
    """The image as float32 (H, W, 4) RGBA: one channel → grey, two → grey + alpha, no alpha → 1; the
    colour channels decoded with the sRGB curve for ``srgb`` (``auto``: integer images), else as stored."""
    import OpenImageIO as oiio

    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(f"path: cannot read image {path.name!r}: {oiio.geterror()}")
    try:
        pixels = image.read_image(0, 0, 0, header.channels, "float")
    finally:
        image.close()
    if pixels is None:
        raise InputError(f"path: cannot decode image {path.name!r}")
    pixels = np.asarray(pixels, dtype=np.float32).reshape(header.height, header.width, header.channels)
    channels = header.channels
    grey = channels <= 2
    rgb = np.repeat(pixels[..., :1], 3, axis=-1) if grey else pixels[..., :3]
    alpha_channel = 1 if grey else 3
    alpha = pixels[..., alpha_channel] if channels > alpha_channel else np.ones(rgb.shape[:2], np.float32)
    if colour_space == "srgb" or (colour_space == "auto" and not header.float_data):
        rgb = srgb_to_linear(np.clip(rgb, 0.0, 1.0)).astype(np.float32)
    return np.concatenate([rgb, alpha[..., None]], axis=-1).astype(np.float32)


def uv_affine_identity() -> list[float]:
    """The affine row of a texture without ``uv_transform``."""
    return [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]


def uv_affine(texture: ImageTexture) -> list[float]:
    """(a, b, c, d, e, f) of uv' = R(θ)·(s ⊙ uv) + o (``schemas.scene.UvTransform``), padded to 8."""
    transform = texture.uv_transform
    if transform is None:
        return [*uv_affine_identity(), 0.0, 0.0]
    theta = math.radians(transform.rotation_deg)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    (su, sv), (ou, ov) = transform.scale, transform.offset
    return [cos_t * su, -sin_t * sv, ou, sin_t * su, cos_t * sv, ov, 0.0, 0.0]


@dataclass
class TextureTable:
    """The scene's bindings, built on the host (module docstring)."""

    coefficients: CoefficientTable | None = None
    texels: list[np.ndarray] = field(default_factory=list)
    layout: list[list[int]] = field(default_factory=list)
    affine: list[list[float]] = field(default_factory=list)
    _size: int = 0

    def __len__(self) -> int:
        return len(self.layout)

    def _add(self, texture: ImageTexture, values: np.ndarray, components: int) -> int:
        height, width = values.shape[:2]
        if self._size % components:  # a texel of several values is one aligned packet gather
            padding = components - self._size % components
            self.texels.append(np.zeros(padding, np.float32))
            self._size += padding
        flags = WRAP_MODES[texture.wrap_u] | WRAP_MODES[texture.wrap_v] << 2 | FILTERS[texture.filter] << 4
        self.layout.append([self._size // components, width, flags, height])
        self.affine.append(uv_affine(texture))
        flat = np.ascontiguousarray(values, dtype=np.float32).ravel()
        self.texels.append(flat)
        self._size += flat.size
        if self._size >= 2**32:
            raise InputError("textures: more than 2³² texel values")
        return len(self.layout) - 1

    def add_scalar(
        self, texture: ImageTexture, rgba: np.ndarray, unit: float, low: float, high: float
    ) -> tuple[int, float, float]:
        """A one-channel binding: offset + scale·x of ``texture.scalar_channel``, times ``unit`` (the
        parameter's unit in SI, e.g. 1e-6 for µm), clipped to [low, high] (SI). Returns (binding, the
        smallest and largest value)."""
        channel = rgba[..., CHANNELS[texture.scalar_channel]].astype(np.float64)
        values = np.clip((texture.offset + texture.scale * channel) * unit, low, high)
        return self._add(texture, values[..., None], 1), float(values.min()), float(values.max())

    def add_colour(self, texture: ImageTexture, rgba: np.ndarray) -> tuple[int, np.ndarray]:
        """A colour binding: linear sRGB offset + scale·x (per channel), clipped to [0, 1], upsampled to
        Jakob–Hanika coefficients (fitted once per distinct colour). Returns (binding, its linear sRGB)."""
        if self.coefficients is None:
            raise InputError("textures: no spectral upsampling table")
        channel = texture.colour_channel
        rgb = rgba[..., :3] if channel == "rgb" else np.repeat(rgba[..., CHANNELS[channel], None], 3, axis=-1)
        scale = np.asarray(texture.scale, dtype=np.float64)
        offset = np.asarray(texture.offset, dtype=np.float64)
        rgb = np.clip(offset + scale * rgb.astype(np.float64), 0.0, 1.0).astype(np.float32)
        colours, inverse = np.unique(rgb.reshape(-1, 3), axis=0, return_inverse=True)
        fitted = fit_coefficients(colours, self.coefficients)
        values = np.zeros((*rgb.shape[:2], COLOUR_COMPONENTS), dtype=np.float32)
        values[..., :3] = fitted[inverse.ravel()].reshape(*rgb.shape[:2], 3)
        return self._add(texture, values, COLOUR_COMPONENTS), rgb

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(texels float32, layout uint32, uv_affine float32), each non-empty."""
        texels = np.concatenate(self.texels) if self.texels else np.zeros(1, np.float32)
        layout = np.asarray(self.layout or [[0] * LAYOUT_STRIDE], dtype=np.uint32).ravel()
        affine = np.asarray(self.affine or [[0.0] * AFFINE_STRIDE], dtype=np.float32).ravel()
        return texels, layout, affine


def coefficient_table() -> CoefficientTable:
    """Jakob & Hanika's sRGB table as shipped with Mitsuba 3 (``mitsuba/data/srgb.coeff``)."""
    import mitsuba

    return CoefficientTable.from_file(Path(mitsuba.__file__).parent / "data" / "srgb.coeff")


class TextureKernels:
    """Texture lookups inside the kernels (module docstring); ``mi`` the Mitsuba module of the variant."""

    def __init__(self, mi: Any, table: TextureTable) -> None:
        texels, layout, affine = table.arrays()
        self.mi = mi
        self.texels = mi.Float(texels)
        self.layout = mi.UInt32(layout)
        self.affine = mi.Float(affine)
        #: whether some binding maps its texture coordinates (else none is read: decided when traced)
        self.transformed = any(row[:6] != uv_affine_identity() for row in table.affine)

    def kernel_tables(self) -> list[Any]:
        return [self.texels, self.layout, self.affine]

    def _footprint(self, binding: Any, uv: Any, active: Any) -> tuple[list[Any], list[Any]]:
        """The (up to) four texels (indices into ``texels`` in units of the binding's texels) and weights of
        ``binding`` at ``uv``; weight 0 where a texel is not read (nearest filtering, ``black`` outside,
        inactive)."""
        import drjit as dr

        mi = self.mi
        layout = dr.gather(mi.Vector4u, self.layout, binding, active)
        first, width_u, flags = layout[0], layout[1], layout[2]
        u, v = uv.x, uv.y
        if self.transformed:
            low = dr.gather(mi.Vector4f, self.affine, binding * 2, active)
            high = dr.gather(mi.Vector4f, self.affine, binding * 2 + 1, active)
            u, v = (
                dr.fma(low[0], uv.x, dr.fma(low[1], uv.y, low[2])),
                dr.fma(low[3], uv.x, dr.fma(high[0], uv.y, high[1])),
            )
        bilinear = (flags & 16) != 0
        columns, column_weights = _axis(u, mi.Float(width_u), flags & 3, bilinear)
        rows, row_weights = _axis(1.0 - v, mi.Float(layout[3]), (flags >> 2) & 3, bilinear)
        indices, weights = [], []
        for row, row_weight in zip(rows, row_weights, strict=True):
            for column, column_weight in zip(columns, column_weights, strict=True):
                weights.append(dr.select(active, row_weight * column_weight, 0.0))
                indices.append(first + mi.UInt32(row) * width_u + mi.UInt32(column))
        return indices, weights

    def scalar(self, binding: Any, uv: Any, active: Any) -> Any:
        """The binding's value at ``uv`` (its parameter's SI units), 0 where not ``active``."""
        import drjit as dr

        indices, weights = self._footprint(binding, uv, active)
        value = self.mi.Float(0.0)
        for index, weight in zip(indices, weights, strict=True):
            value += weight * dr.gather(self.mi.Float, self.texels, index, weight > 0.0)
        return value

    def reflectance(self, binding: Any, uv: Any, wavelengths: Any, active: Any) -> Any:
        """The binding's filtered reflectance spectrum at ``uv`` and the path's ``wavelengths`` (nm)."""
        import drjit as dr

        from worker.render.drjit_ops import drjit_ops

        mi, ops = self.mi, drjit_ops()
        indices, weights = self._footprint(binding, uv, active)
        result = mi.Spectrum(0.0)
        for index, weight in zip(indices, weights, strict=True):
            coefficients = dr.gather(mi.Vector4f, self.texels, index, weight > 0.0)
            c = (coefficients[0], coefficients[1], coefficients[2])
            for j in range(len(wavelengths)):
                result[j] += weight * sigmoid_polynomial(c, wavelengths[j], ops)
        return result


def _axis(coordinate: Any, size: Any, mode: Any, bilinear: Any) -> tuple[list[Any], list[Any]]:
    """Texel indices (floats in [0, size)) and weights of the two texels along one axis around
    ``coordinate`` (a texture coordinate: u, or 1 − v) for the wrap ``mode`` and filter (per lane; module
    docstring): the texels around t·size − ½ (bilinear) or the texel t·size falls in (nearest, weights
    1 and 0)."""
    import drjit as dr

    repeat, mirror, black = (
        mode == WRAP_MODES["repeat"],
        mode == WRAP_MODES["mirror"],
        mode == WRAP_MODES["black"],
    )
    folded = coordinate - 2.0 * dr.floor(0.5 * coordinate)  # [0, 2)
    mirrored = dr.select(folded < 1.0, folded, 2.0 - folded)
    t = dr.select(repeat, coordinate - dr.floor(coordinate), dr.select(mirror, mirrored, coordinate))
    position = t * size - dr.select(bilinear, 0.5, 0.0)
    low = dr.floor(position)
    fraction = dr.select(bilinear, position - low, 0.0)
    indices, weights = [], []
    for index, weight in ((low, 1.0 - fraction), (low + 1.0, fraction)):
        inside = (index >= 0.0) & (index < size)
        across = dr.select(index < 0.0, index + size, index - size)  # the seam: −1 → size − 1, size → 0
        wrapped = dr.select(repeat & ~inside, across, dr.clip(index, 0.0, size - 1.0))
        indices.append(dr.clip(wrapped, 0.0, size - 1.0))
        weights.append(dr.select(black & ~inside, 0.0, weight))
    return indices, weights
