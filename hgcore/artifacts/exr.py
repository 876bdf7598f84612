"""The one OpenEXR reader and writer of hgrender (OpenImageIO).

``read_exr`` returns every channel of the first subimage as float32 (H, W) arrays with the header's
string attributes; ``write_exr`` writes float32 channels, ZIP-compressed, atomically (a temporary file in
the same directory, then ``os.replace``), so a reader never sees half a file. Every failure to read or
write an image is an :class:`ArtifactFormatError` naming the file, never a bare ``OSError`` or ``None``.
"""

from __future__ import annotations

from collections.abc import Sequence
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
    import OpenImageIO as oiio

    if not channels:
        raise ArtifactFormatError(f"{Path(path).name}: an EXR needs at least one channel")
    height, width = channels[0][1].shape
    pixels = np.stack([data for _, data in channels], axis=-1).astype(np.float32)
    spec = oiio.ImageSpec(width, height, len(channels), "float")
    spec.channelnames = tuple(name for name, _ in channels)
    spec.attribute("compression", "zip")
    for key, value in attributes.items():
        spec.attribute(key, value)
    path = Path(path)
    with atomic_output(path, suffix=".exr") as temporary:
        output = oiio.ImageOutput.create(str(temporary))
        if output is None or not output.open(str(temporary), spec):
            raise ArtifactFormatError(f"{path.name}: cannot be written ({_oiio_reason(oiio)})")
        written = output.write_image(pixels)
        output.close()
        if not written:
            raise ArtifactFormatError(f"{path.name}: cannot be written ({_oiio_reason(oiio)})")


def _oiio_reason(oiio: object) -> str:
    """OpenImageIO's last error without the temporary paths it may name (never echo internal paths)."""
    message = str(oiio.geterror()).strip()  # type: ignore[attr-defined]
    return message.rsplit(": ", 1)[-1] if message else "unknown error"
