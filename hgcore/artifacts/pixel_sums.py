"""Per-pixel sums of a render or chunk (NumPy only, so the service can read chunk partials).

A render's result before normalisation: for every pixel the sums over its samples of each band's
estimate, of its square (for the variance of the mean), and of the diagnostics and AOV terms
(``SUM_KEYS``). Chunks merge by adding sums; dividing by ``sample_count`` gives the images.

A chunk partial (``.npz``, uncompressed: zlib on float data costs more than it saves) holds the sums as
float32 (``PixelSums.to_arrays``) plus the chunk's render time ``seconds``, ``chunk_index`` and ``seed``.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hgcore.files import atomic_write_bytes

SUM_KEYS = (
    "diag_w",
    "diag_mxx",
    "diag_mxy",
    "diag_myy",
    "diag_r",
    "diag_c2",
    "diag_s2",
    "vcz_w",
    "vcz_w2",
    "vcz_r",
    "vcz_dx",
    "vcz_dxx",
    "vcz_dxy",
    "vcz_dxz",
    "vcz_dy",
    "vcz_dyy",
    "vcz_dyz",
    "vcz_dz",
    "vcz_dzz",
    "depth",
    "normal_x",
    "normal_y",
    "normal_z",
    "albedo_x",
    "albedo_y",
    "albedo_z",
    "luminance",
    "luminance_sq",
)


@dataclass
class PixelSums:
    """Per-pixel sums over ``sample_count`` samples per pixel (float64, shape (H, W[, B]))."""

    sample_count: int
    bands: np.ndarray
    bands_sq: np.ndarray
    values: dict[str, np.ndarray]

    def add(self, other: PixelSums) -> PixelSums:
        return PixelSums(
            self.sample_count + other.sample_count,
            self.bands + other.bands,
            self.bands_sq + other.bands_sq,
            {key: self.values[key] + other.values[key] for key in self.values},
        )

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays for a chunk partial. float32 halves the file and keeps 7 significant digits of each sum,
        far below the Monte Carlo error of any pixel; merges add them in float64."""
        return {
            "sample_count": np.array(self.sample_count),
            "bands": self.bands.astype(np.float32),
            "bands_sq": self.bands_sq.astype(np.float32),
            **{f"v_{key}": value.astype(np.float32) for key, value in self.values.items()},
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> PixelSums:
        return cls(
            int(arrays["sample_count"]),
            arrays["bands"].astype(np.float64),
            arrays["bands_sq"].astype(np.float64),
            {key: arrays[f"v_{key}"].astype(np.float64) for key in SUM_KEYS},
        )


def write_partial(path: Path, sums: PixelSums, seconds: float, chunk_index: int, seed: int) -> None:
    """Write a chunk's sums and render time (seconds) to ``path`` (.npz, atomic)."""
    buffer = io.BytesIO()
    np.savez(
        buffer,
        **sums.to_arrays(),
        seconds=np.array(seconds),
        chunk_index=np.array(chunk_index),
        seed=np.array(seed),
    )
    atomic_write_bytes(Path(path), buffer.getvalue())


def read_partial(path: Path) -> tuple[PixelSums, float]:
    """A chunk partial's sums and its render time (seconds)."""
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    return PixelSums.from_arrays(arrays), float(arrays["seconds"])
