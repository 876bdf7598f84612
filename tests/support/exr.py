"""The renderer's OpenEXR outputs as float64 arrays, read with the project's one EXR reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hgcore.artifacts.exr import read_exr


def read_channels(path: Path) -> dict[str, np.ndarray]:
    """Every channel of the EXR at ``path`` as a float64 (H, W) array, keyed by channel name."""
    return {name: values.astype(np.float64) for name, values in read_exr(path).channels.items()}


def spectral_stack(channels: dict[str, np.ndarray]) -> tuple[list[str], np.ndarray]:
    """The ``S0.<λ>nm`` channels in file order and their (H, W, B) stack."""
    names = [name for name in channels if name.startswith("S0.")]
    return names, np.stack([channels[name] for name in names], axis=-1)
