"""Per-pixel sums of a render or chunk (NumPy only, so the service can read chunk partials).

A render's result before normalisation: for every pixel the sums over its samples of each band's
estimate, of its square (for the variance of the mean), and of the diagnostics and AOV terms
(``SUM_KEYS``). Chunks merge by adding sums; dividing by ``sample_count`` gives the images.

A chunk partial (``.npz``, uncompressed: zlib on float data costs more than it saves) holds the sums as
one float32 array ``sums`` of shape (H, W, C), C = 2B + len(SUM_KEYS) columns in the order bands,
bands², ``SUM_KEYS``, plus ``sample_count``, ``band_count`` and the chunk's render time ``seconds``,
``chunk_index`` and ``seed``. ``PartialWriter`` streams it row band by row band and ``PartialReader``
reads any rows back (the member is stored, so its rows lie at a fixed offset in the file): neither ever
holds more than one band of the image.

A chunk's sums are rounded to float32 once (``PixelSums.rounded``) whether they go through a partial or
stay in memory, then added in float64: a job's image is bitwise the same however its chunks travelled.
"""

from __future__ import annotations

import contextlib
import struct
import zipfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from hgcore.files import atomic_output

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

    @property
    def rows(self) -> int:
        return int(self.bands.shape[0])

    def row_slice(self, y0: int, y1: int) -> PixelSums:
        """The sums of rows [y0, y1) (views, no copy)."""
        return PixelSums(
            self.sample_count,
            self.bands[y0:y1],
            self.bands_sq[y0:y1],
            {key: value[y0:y1] for key, value in self.values.items()},
        )

    def rounded(self) -> PixelSums:
        """The sums rounded to float32 (what a chunk partial stores), as float64. float32 keeps 7
        significant digits of each sum, far below the Monte Carlo error of any pixel."""

        def f32(values: np.ndarray) -> np.ndarray:
            return values.astype(np.float32).astype(np.float64)

        return PixelSums(
            self.sample_count,
            f32(self.bands),
            f32(self.bands_sq),
            {key: f32(value) for key, value in self.values.items()},
        )

    def table(self, dtype: type[np.floating] = np.float32) -> np.ndarray:
        """The sums as one (rows, W, C) array in the partial's column order (float32: what a partial
        stores; float64: what ``RunningSums`` keeps)."""
        columns = [self.bands, self.bands_sq, *(self.values[key][..., None] for key in SUM_KEYS)]
        return np.concatenate(columns, axis=-1).astype(dtype, copy=False)

    @classmethod
    def from_table(cls, sample_count: int, band_count: int, table: np.ndarray) -> PixelSums:
        """Sums (float64) from a (rows, W, C) table in the partial's column order (views of a float64
        table, not copies)."""
        table = table.astype(np.float64, copy=False)
        return cls(
            sample_count,
            table[..., :band_count],
            table[..., band_count : 2 * band_count],
            {key: table[..., 2 * band_count + i] for i, key in enumerate(SUM_KEYS)},
        )

    @classmethod
    def concatenate(cls, parts: list[PixelSums]) -> PixelSums:
        """Row bands (top to bottom, equal ``sample_count``) stacked into one image (one band: itself)."""
        if len(parts) == 1:
            return parts[0]
        return cls(
            parts[0].sample_count,
            np.concatenate([part.bands for part in parts]),
            np.concatenate([part.bands_sq for part in parts]),
            {key: np.concatenate([part.values[key] for part in parts]) for key in SUM_KEYS},
        )


def variance_of_mean(total: np.ndarray, total_sq: np.ndarray, count: int) -> np.ndarray:
    """σ̂²/N, the variance of the mean of ``count`` samples from their sum and sum of squares with the 1/N
    sample variance σ̂² = Σx²/N − x̄² (variance.exr's definition; readers that need it unbiased scale by
    N/(N−1), ``hgcore.regression.images``)."""
    mean = total / count
    return np.maximum(total_sq / count - mean * mean, 0.0) / count


def column_count(band_count: int) -> int:
    """Columns of a partial's table: bands, bands² and ``SUM_KEYS``."""
    return 2 * band_count + len(SUM_KEYS)


_TABLE = "sums.npy"


class PartialWriter:
    """Streams a chunk partial's table into an open archive: ``write_rows`` in image order, then
    ``finish`` (see ``partial_writer``)."""

    def __init__(self, archive: zipfile.ZipFile, width: int, height: int, band_count: int) -> None:
        self.width, self.height, self.band_count = width, height, band_count
        self.rows_written = 0
        self.finished = False
        self._archive = archive
        self.member: IO[bytes] = archive.open(_TABLE, "w", force_zip64=True)
        shape = (height, width, column_count(band_count))
        header = {"descr": "<f4", "fortran_order": False, "shape": shape}
        np.lib.format.write_array_header_2_0(self.member, header)  # type: ignore[no-untyped-call]

    def write_rows(self, sums: PixelSums) -> None:
        """Append the next rows (their sums, float32-rounded like every chunk's)."""
        if self.rows_written + sums.rows > self.height:
            raise ValueError(f"partial: more than {self.height} rows written")
        self.rows_written += sums.rows
        self.member.write(sums.table().tobytes())

    def finish(self, sample_count: int, seconds: float, chunk_index: int, seed: int) -> None:
        """Close the table and write the scalars."""
        if self.rows_written != self.height:
            raise ValueError(f"partial: {self.rows_written} of {self.height} rows written")
        self.member.close()
        scalars = {
            "sample_count": sample_count,
            "band_count": self.band_count,
            "seconds": seconds,
            "chunk_index": chunk_index,
            "seed": seed,
        }
        for name, value in scalars.items():
            with self._archive.open(f"{name}.npy", "w") as member:
                np.lib.format.write_array(member, np.array(value))  # type: ignore[no-untyped-call]
        self.finished = True


@contextlib.contextmanager
def partial_writer(path: Path, width: int, height: int, band_count: int) -> Iterator[PartialWriter]:
    """A ``PartialWriter`` on ``path``; the file appears (atomically) only if the block called
    ``finish``, so an interrupted chunk never leaves half a partial."""
    with (
        atomic_output(Path(path), suffix=".npz") as temporary,
        zipfile.ZipFile(temporary, "w", zipfile.ZIP_STORED) as archive,
    ):
        writer = PartialWriter(archive, width, height, band_count)
        try:
            yield writer
        finally:
            writer.member.close()  # the archive cannot close while a member is open for writing
        if not writer.finished:
            raise ValueError(f"{Path(path).name}: the partial was not finished")


class PartialReader:
    """A chunk partial's scalars and any rows of its sums, read from the file (never the whole table)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        with zipfile.ZipFile(self.path) as archive:
            scalars = {}
            for name in ("sample_count", "band_count", "seconds", "chunk_index", "seed"):
                with archive.open(f"{name}.npy") as member:
                    scalars[name] = np.lib.format.read_array(member)  # type: ignore[no-untyped-call]
            info = archive.getinfo(_TABLE)
        self.sample_count = int(scalars["sample_count"])
        self.band_count = int(scalars["band_count"])
        self.seconds = float(scalars["seconds"])
        self.chunk_index = int(scalars["chunk_index"])
        self.seed = int(scalars["seed"])
        with open(self.path, "rb") as file:
            # A stored member's data follows its local header: 30 bytes, then its name and extra field.
            file.seek(info.header_offset)
            local = file.read(30)
            name_length, extra_length = struct.unpack("<HH", local[26:30])
            file.seek(info.header_offset + 30 + name_length + extra_length)
            version = np.lib.format.read_magic(file)  # type: ignore[no-untyped-call]
            read_header = (
                np.lib.format.read_array_header_1_0
                if version == (1, 0)
                else np.lib.format.read_array_header_2_0
            )
            shape, _, dtype = read_header(file)  # type: ignore[operator]
            self._offset = file.tell()
        self.height, self.width, self._columns = shape
        self._dtype = np.dtype(dtype)

    def rows(self, y0: int, y1: int) -> PixelSums:
        """The sums (float64) of rows [y0, y1)."""
        row_values = self.width * self._columns
        with open(self.path, "rb") as file:
            file.seek(self._offset + y0 * row_values * self._dtype.itemsize)
            table = np.fromfile(file, dtype=self._dtype, count=(y1 - y0) * row_values)
        table = table.reshape(y1 - y0, self.width, self._columns)
        return PixelSums.from_table(self.sample_count, self.band_count, table)


def write_partial(
    path: Path,
    sums: PixelSums,
    seconds: float,
    chunk_index: int,
    seed: int,
    rows_per_write: int | None = None,
) -> None:
    """Write a chunk's sums (whole image) and render time (seconds) to ``path`` (.npz, atomic);
    ``rows_per_write`` rows at a time (default: all), so that only that band's float32 table exists."""
    height, width, band_count = sums.bands.shape
    step = height if rows_per_write is None else max(1, rows_per_write)
    row_bands = (sums.row_slice(y0, y0 + step) for y0 in range(0, height, step))
    write_partial_rows(
        path, width, height, band_count, row_bands, sums.sample_count, seconds, chunk_index, seed
    )


def write_partial_rows(
    path: Path,
    width: int,
    height: int,
    band_count: int,
    row_bands: Iterable[PixelSums],
    sample_count: int,
    seconds: float,
    chunk_index: int,
    seed: int,
) -> None:
    """Write a chunk partial from its row bands (top to bottom, covering the image) to ``path`` (atomic)."""
    with partial_writer(path, width, height, band_count) as writer:
        for rows in row_bands:
            writer.write_rows(rows)
        writer.finish(sample_count, seconds, chunk_index, seed)


def read_partial(path: Path) -> tuple[PixelSums, float]:
    """A chunk partial's sums (whole image) and its render time (seconds)."""
    reader = PartialReader(path)
    return reader.rows(0, reader.height), reader.seconds


def iter_merged_rows(readers: list[PartialReader], row_bands: list[tuple[int, int]]) -> Iterator[PixelSums]:
    """The partials' sums added, one row band at a time (in ``readers``' order: a fixed float64 sum)."""
    for y0, y1 in row_bands:
        total = readers[0].rows(y0, y1)
        for reader in readers[1:]:
            total = total.add(reader.rows(y0, y1))
        yield total
