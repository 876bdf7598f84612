"""Reading the renderer's OpenEXR outputs back with OpenImageIO, channel by channel."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio


def read_channels(path: Path) -> dict[str, np.ndarray]:
    """Every channel of the EXR at ``path`` as a float64 (H, W) array, keyed by channel name."""
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    names = list(image.spec().channelnames)
    pixels = np.asarray(image.read_image("float"), dtype=np.float64)
    image.close()
    return {name: pixels[..., index] for index, name in enumerate(names)}


def spectral_stack(channels: dict[str, np.ndarray]) -> tuple[list[str], np.ndarray]:
    """The ``S0.<λ>nm`` channels in file order and their (H, W, B) stack."""
    names = [name for name in channels if name.startswith("S0.")]
    return names, np.stack([channels[name] for name in names], axis=-1)
