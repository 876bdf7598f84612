"""A whole image's running per-pixel sums kept on disk, one row band in memory at a time.

A noise-target render adds rounds until a statistic over all pixels meets its target
(``hgcore.noise_target``), so every pixel's sums must survive from one round to the next. Held in memory
they are the image: at 1024² × 32 bands one float64 copy is 0.77 GB (92 columns: bands, bands², the
``SUM_KEYS``), and adding a round to it made two more (measured peak RSS of such a render: 3.7 GB, against
1.26 GB for a fixed-spp one). Here they live in an anonymous temporary file (unlinked at once: nothing is
left behind, even by a killed process) as float64 rows in the chunk partial's column order, read and
written with positioned I/O. The page cache serves those reads without counting towards the process's
resident set, as a memory map's pages would.

Chunks are added in float64, in chunk order, row band by row band, as ``PixelSums.add`` adds whole
images: the sums, and hence the images, are bitwise those of the whole-image addition.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from hgcore.artifacts.pixel_sums import SUM_KEYS, PixelSums, column_count

_FLOAT64 = np.dtype(np.float64)


class RunningSums:
    """The running sums of a ``width`` × ``height`` image with ``band_count`` bands, stored in a
    temporary file in ``directory`` (default: the system's). Chunks (a noise-target round is one or more)
    are added whole, one after the other: ``add_rows`` for each of the image's row bands, then
    ``finish_chunk``; ``sample_count`` counts the samples per pixel of the chunks finished."""

    def __init__(self, width: int, height: int, band_count: int, directory: Path | None = None) -> None:
        self.width, self.height, self.band_count = width, height, band_count
        self.columns = column_count(band_count)
        self.sample_count = 0
        self._file = tempfile.TemporaryFile(dir=directory)  # noqa: SIM115 (closed by close()/__exit__)
        self._row_bytes = width * self.columns * _FLOAT64.itemsize

    def add_rows(self, y0: int, sums: PixelSums) -> PixelSums:
        """Add a chunk's sums of rows [y0, y0 + rows) to the stored ones (the first chunk stores them)
        and return the rows' running sums (``sample_count`` + the chunk's)."""
        if self.sample_count > 0:
            # Added in place to the stored rows' table (the same float64 additions as PixelSums.add, so
            # the same bits), which is then written back as it is: one table of the rows in memory.
            table = self._read_table(y0, y0 + sums.rows)
            running = PixelSums.from_table(self.sample_count, self.band_count, table)  # views of it
            running.bands += sums.bands
            running.bands_sq += sums.bands_sq
            for key in SUM_KEYS:
                running.values[key] += sums.values[key]
            running.sample_count += sums.sample_count
        else:
            running = sums
            table = sums.table(np.float64)
        os.pwrite(self._file.fileno(), memoryview(table).cast("B"), y0 * self._row_bytes)  # no copy
        return running

    def finish_chunk(self, spp: int) -> None:
        """Every row band has had the chunk of ``spp`` samples per pixel added."""
        self.sample_count += spp

    def rows(self, y0: int, y1: int) -> PixelSums:
        """The stored sums of rows [y0, y1) after the finished chunks."""
        return PixelSums.from_table(self.sample_count, self.band_count, self._read_table(y0, y1))

    def _read_table(self, y0: int, y1: int) -> np.ndarray:
        """Rows [y0, y1) as a (rows, W, C) float64 table, read straight into it (no intermediate copy)."""
        table = np.empty((y1 - y0, self.width, self.columns), dtype=_FLOAT64)
        read = os.preadv(self._file.fileno(), [memoryview(table).cast("B")], y0 * self._row_bytes)
        if read != table.nbytes:
            raise ValueError(f"rows {y0}–{y1}: not stored yet")
        return table

    def row_bands(self, bands: Iterable[tuple[int, int]]) -> Iterator[PixelSums]:
        """The stored sums, one row band (y0, y1) at a time."""
        for y0, y1 in bands:
            yield self.rows(y0, y1)

    def whole(self) -> PixelSums:
        """Every row at once (memory ∝ the image: only for callers that need the whole image)."""
        return self.rows(0, self.height)

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> RunningSums:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
