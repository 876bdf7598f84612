"""Image files for tests that need textures or environment maps (written with OpenImageIO)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def write_image(path: Path, pixels: np.ndarray) -> Path:
    """Write (H, W, C) ``pixels`` to ``path``: uint8 arrays as 8-bit (PNG/JPEG), float arrays as float32
    (EXR)."""
    import OpenImageIO as oiio

    array = np.ascontiguousarray(pixels)
    if array.ndim == 2:
        array = array[..., None]
    pixel_format = "uint8" if array.dtype == np.uint8 else "float"
    if pixel_format == "float":
        array = array.astype(np.float32)
    output = oiio.ImageOutput.create(str(path))
    assert output is not None, oiio.geterror()
    spec = oiio.ImageSpec(array.shape[1], array.shape[0], array.shape[2], pixel_format)
    assert output.open(str(path), spec), output.geterror()
    assert output.write_image(array), output.geterror()
    output.close()
    return path


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve (IEC 61966-2-1): linear values in [0, 1] → encoded."""
    values = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(values <= 0.0031308, 12.92 * values, 1.055 * values ** (1.0 / 2.4) - 0.055)


def sky_image(
    width: int, height: int, patch: tuple[slice, slice], patch_rgb: tuple[float, float, float]
) -> np.ndarray:
    """A lat-long HDR sky (float32 (H, W, 3), OpenEXR orientation): a blue-to-white gradient above the
    horizon, a brown ground below, and a bright rectangle of texels ``patch`` (rows, columns) of colour
    ``patch_rgb`` (a sun-like source for importance sampling)."""
    rows = (np.arange(height) + 0.5) / height  # 0 at the zenith
    elevation = (0.5 - rows) * math.pi
    sky = np.where(
        elevation[:, None, None] > 0.0,
        np.array([0.35, 0.5, 0.9]) + 0.5 * (1.0 - np.sin(elevation))[:, None, None],
        np.array([0.25, 0.18, 0.1]),
    )
    image = np.broadcast_to(sky, (height, width, 3)).copy()
    image[patch] = patch_rgb
    return image.astype(np.float32)
