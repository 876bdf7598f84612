"""The image files a scene reads (material textures, environment maps): where, their headers, their limits.

Every image is checked from its header alone (OpenImageIO opens the file and reads its spec, no pixels)
before anything decodes it: it must be a file inside the bundle (``schemas.bundle.resolve_bundle_file``),
at most ``HGRENDER_MAX_FILE_BYTES``, readable as an image, at most ``HGRENDER_MAX_TEXTURE_PIXELS``
(width × height), and all of a scene's images together at most ``HGRENDER_MAX_TEXTURE_BYTES`` decoded
(width × height × channels × 4 bytes of float32). The number of distinct files is bounded by
``HGRENDER_MAX_TEXTURES`` on the raw document (``schemas.validation.document_image_pointers``, before the
schema). Errors are
``SceneError``s at the JSON pointer of the field that names the file (``/materials/wood/reflectance/path``,
``/emitters/2/path``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from hgcore.settings import SceneLimits
from schemas.errors import SceneError, json_pointer
from schemas.scene import EnvironmentEmitter, ImageTexture, Scene

#: Bytes of one decoded channel value (images are decoded to float32).
DECODED_BYTES_PER_CHANNEL = 4


@dataclass(frozen=True)
class ImageReference:
    """An image a scene reads: the JSON pointer of the field naming it, its bundle path and, for a material
    parameter, the texture (None for an environment map) and the parameter's name."""

    pointer: str
    path: str
    texture: ImageTexture | None = None


@dataclass(frozen=True)
class ImageHeader:
    """What an image's header says: size, channel count and whether its values are stored as floats."""

    width: int
    height: int
    channels: int
    float_data: bool

    @property
    def decoded_bytes(self) -> int:
        return self.width * self.height * self.channels * DECODED_BYTES_PER_CHANNEL


def image_references(scene: Scene) -> Iterator[ImageReference]:
    """Every image reference of a validated scene, materials first (in document order)."""
    for material_id, material in scene.materials.items():
        for field_name in type(material).model_fields:
            value = getattr(material, field_name)
            if isinstance(value, ImageTexture):
                yield ImageReference(json_pointer(["materials", material_id, field_name]), value.path, value)
    for index, emitter in enumerate(scene.emitters):
        if isinstance(emitter, EnvironmentEmitter) and emitter.path is not None:
            yield ImageReference(json_pointer(["emitters", index]), emitter.path)


def require_no_images(scene: Scene, reason: str) -> None:
    """A SceneError at the first image the scene names, saying ``reason`` (a scene that comes without its
    bundle cannot read files: JSON bodies and JSON files over HTTP)."""
    for reference in image_references(scene):
        raise SceneError.at(f"{reference.pointer}/path", f"image {reference.path!r}: {reason}")


def read_image_header(path: Path, where: str) -> ImageHeader:
    """The header of the image file at ``path`` (OpenImageIO reads the spec only); a SceneError at
    ``where`` naming the file if it cannot be read as an image."""
    import OpenImageIO as oiio

    image = oiio.ImageInput.open(str(path))
    if image is None:
        message = oiio.geterror().replace(str(path), path.name) or "unknown format"
        raise SceneError.at(where, f"cannot read image {path.name!r}: {message}")
    try:
        spec = image.spec()
        base = spec.format.basetype
        float_data = base in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE)
        return ImageHeader(int(spec.width), int(spec.height), int(spec.nchannels), float_data)
    finally:
        image.close()


def check_image(
    bundle_dir: Path, relative_path: str, limits: SceneLimits, where: str
) -> tuple[Path, ImageHeader]:
    """The image file at ``relative_path`` (confined to the bundle) and its header, within the size limits."""
    from schemas.bundle import resolve_bundle_file  # (USD's libraries: only where a bundle is read)

    path = resolve_bundle_file(bundle_dir, relative_path, where)
    size_bytes = path.stat().st_size
    if size_bytes > limits.max_file_bytes:
        raise SceneError.at(
            where,
            f"image {relative_path!r} of {size_bytes} bytes exceeds the limit of {limits.max_file_bytes} "
            "(HGRENDER_MAX_FILE_BYTES)",
        )
    header = read_image_header(path, where)
    if header.width < 1 or header.height < 1 or header.channels < 1:
        raise SceneError.at(where, f"image {relative_path!r} has no pixels")
    pixels = header.width * header.height
    if pixels > limits.max_texture_pixels:
        raise SceneError.at(
            where,
            f"image {relative_path!r} of {header.width}×{header.height} pixels exceeds the limit of "
            f"{limits.max_texture_pixels} (HGRENDER_MAX_TEXTURE_PIXELS)",
        )
    return path, header


def check_scene_images(
    scene: Scene, bundle_dir: Path | None, limits: SceneLimits | None = None
) -> dict[str, tuple[Path, ImageHeader]]:
    """Check every image the scene reads (module docstring); returns bundle path → (file, header)."""
    limits = limits if limits is not None else SceneLimits()
    checked: dict[str, tuple[Path, ImageHeader]] = {}
    total_bytes = 0
    for reference in image_references(scene):
        where = f"{reference.pointer}/path"
        if reference.path in checked:
            continue
        if bundle_dir is None:
            message = f"image {reference.path!r} needs a bundle (a folder or zip with the scene)"
            raise SceneError.at(where, message)
        path, header = check_image(bundle_dir, reference.path, limits, where)
        total_bytes += header.decoded_bytes
        if total_bytes > limits.max_texture_bytes:
            raise SceneError.at(
                where,
                f"images decode to {total_bytes} bytes with {reference.path!r}, over the limit of "
                f"{limits.max_texture_bytes} (HGRENDER_MAX_TEXTURE_BYTES)",
            )
        checked[reference.path] = (path, header)
    return checked
