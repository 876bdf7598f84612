"""The one OpenEXR reader and writer of hgrender (OpenImageIO).

``read_exr`` returns every channel of the first subimage as float32 (H, W) arrays with the header's
string attributes; ``write_exr`` (whole images) and ``exr_scanline_writer`` (row band by row band,
for images that do not fit in memory at once) write float32 channels, ZIP-compressed, atomically (a
temporary file in the same directory, then ``os.replace``), so a reader never sees half a file. Every
failure to read or write an image is an :class:`ArtifactFormatError` naming the file, never a bare
``OSError`` or ``None``.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hgcore.artifacts.layout import RGB_CHANNELS, is_spectral_channel, spectral_channel_wavelength_nm
from hgcore.files import atomic_output


class ArtifactFormatError(ValueError):
    """An artifact that cannot be read or written, or lacks what its format requires."""


@dataclass
class ExrImage:
    """The channels of one EXR file: float32 (H, W) arrays keyed by channel name, in file order."""

    width: int
    height: int
    channels: dict[str, np.ndarray]
    attributes: dict[str, str] = field(default_factory=dict)

    def stack(self, names: Sequence[str] | None = None) -> np.ndarray:
        """The channels ``names`` (default: all, in file order) stacked along a last axis, (H, W, C)."""
        chosen = list(self.channels) if names is None else list(names)
        self.require(chosen, "image")
        return np.stack([self.channels[name] for name in chosen], axis=-1)

    @property
    def rgb(self) -> np.ndarray:
        """The linear-sRGB preview channels ``R``, ``G``, ``B`` stacked, (H, W, 3)."""
        return self.stack(RGB_CHANNELS)

    def band_names(self) -> list[str]:
        """The spectral channel names, by wavelength."""
        return [name for _, name in self.spectral_channels()]

    def spectral_channels(self) -> list[tuple[float, str]]:
        """(band centre in nm, channel name) of the spectral ``S0.<λ>nm`` channels, by wavelength."""
        names = [name for name in self.channels if is_spectral_channel(name)]
        return sorted((spectral_channel_wavelength_nm(name), name) for name in names)

    def require(self, names: Sequence[str], what: str) -> None:
        """ArtifactFormatError naming ``what`` (the file) unless every channel in ``names`` is present."""
        missing = [name for name in names if name not in self.channels]
        if missing:
            raise ArtifactFormatError(f"{what}: lacks the channels {missing}")


def read_exr(path: Path) -> ExrImage:
    """Every channel of ``path`` (first subimage) as float32 (H, W) arrays, plus string attributes."""
    import OpenImageIO as oiio

    image_input = oiio.ImageInput.open(str(path))
    if image_input is None:
        raise ArtifactFormatError(f"{Path(path).name}: not a readable EXR image ({_oiio_reason(oiio)})")
    try:
        spec = image_input.spec()
        pixels = image_input.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        attributes = {
            attribute.name: str(attribute.value)
            for attribute in spec.extra_attribs
            if isinstance(attribute.value, str)
        }
    finally:
        image_input.close()
    if pixels is None:
        raise ArtifactFormatError(f"{Path(path).name}: its pixels cannot be read ({_oiio_reason(oiio)})")
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    channels = {name: np.ascontiguousarray(pixels[..., i]) for i, name in enumerate(spec.channelnames)}
    return ExrImage(spec.width, spec.height, channels, attributes)


def write_exr(path: Path, channels: Sequence[tuple[str, np.ndarray]], attributes: dict[str, str]) -> None:
    """Write (name, (H, W) array) ``channels`` as float32 with ``attributes``, atomically."""
    if not channels:
        raise ArtifactFormatError(f"{Path(path).name}: an EXR needs at least one channel")
    height, width = channels[0][1].shape
    with exr_scanline_writer(path, width, height, [name for name, _ in channels], attributes) as writer:
        writer.write_rows(0, [data for _, data in channels])


class ExrScanlineWriter:
    """An open EXR being written row band by row band (OpenImageIO scanline writes, top to bottom)."""

    def __init__(self, output: object, name: str, width: int, height: int, channel_count: int) -> None:
        self._output, self._name = output, name
        self.width, self.height, self.channel_count = width, height, channel_count
        self.rows_written = 0

    def write_rows(self, y0: int, channels: Sequence[np.ndarray]) -> None:
        """Rows [y0, y0 + rows) of every channel ((rows, W) arrays, file order); y0 continues the file."""
        import OpenImageIO as oiio

        if len(channels) != self.channel_count or y0 != self.rows_written:
            raise ArtifactFormatError(f"{self._name}: rows must come in order with every channel")
        pixels = np.ascontiguousarray(np.stack(channels, axis=-1), dtype=np.float32)
        rows = pixels.shape[0]
        if not self._output.write_scanlines(y0, y0 + rows, 0, pixels):  # type: ignore[attr-defined]
            raise ArtifactFormatError(f"{self._name}: cannot be written ({_oiio_reason(oiio)})")
        self.rows_written += rows


@contextmanager
def exr_scanline_writer(
    path: Path, width: int, height: int, channel_names: Sequence[str], attributes: dict[str, str]
) -> Iterator[ExrScanlineWriter]:
    """An ``ExrScanlineWriter`` for a float32, ZIP-compressed EXR at ``path``: the file appears
    (atomically) when the block ends with every row written; memory holds one row band, not the image."""
    import OpenImageIO as oiio

    path = Path(path)
    if not channel_names:
        raise ArtifactFormatError(f"{path.name}: an EXR needs at least one channel")
    spec = oiio.ImageSpec(width, height, len(channel_names), "float")
    spec.channelnames = tuple(channel_names)
    spec.attribute("compression", "zip")
    for key, value in attributes.items():
        spec.attribute(key, value)
    with atomic_output(path, suffix=".exr") as temporary:
        output = oiio.ImageOutput.create(str(temporary))
        if output is None or not output.open(str(temporary), spec):
            raise ArtifactFormatError(f"{path.name}: cannot be written ({_oiio_reason(oiio)})")
        writer = ExrScanlineWriter(output, path.name, width, height, len(channel_names))
        try:
            yield writer
        finally:
            closed = output.close()
        if writer.rows_written != height or not closed:
            raise ArtifactFormatError(f"{path.name}: cannot be written ({_oiio_reason(oiio)})")


def _oiio_reason(oiio: object) -> str:
    """OpenImageIO's last error without the temporary paths it may name (never echo internal paths)."""
    message = str(oiio.geterror()).strip()  # type: ignore[attr-defined]
    return message.rsplit(": ", 1)[-1] if message else "unknown error"
