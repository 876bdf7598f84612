"""Turning a job request into a validated scene: JSON bodies, uploaded JSON files, USD files.

The request's ``spp``, ``seed`` and ``integrator`` override the scene's ``film.spp`` / ``film.seed`` /
``film.integrator``, and the deployment's scene limits (``hgcore.settings.SceneLimits``) apply to the
values that will actually be rendered: a JSON scene has the overrides written into its document, which is
then validated once; a USD stage is validated by its importer, and overridden and validated again
(``schemas.with_film_overrides``) only when the request overrides something. From here on the scene
travels as the typed ``schemas.Scene``. Invalid input raises ``schemas.SceneError`` (JSON pointers into
the scene) or ValueError; nothing is written or enqueued before this succeeds.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from hgcore.settings import SceneLimits
from schemas import Scene, SceneError, validate_scene, with_film_overrides
from schemas.textures import require_no_images
from schemas.validation import load_scene_json, override_film
from service.models import JobOptions

USD_SUFFIXES: tuple[str, ...] = (".usda", ".usdc", ".usd", ".usdz", ".zip")


def film_overrides(options: JobOptions) -> dict[str, Any]:
    """The film fields a request overrides (None: keep the scene's)."""
    return {"spp": options.spp, "seed": options.seed, "integrator": options.integrator}


#: Why a JSON scene over HTTP cannot name an image: it has no bundle to read it from.
NO_BUNDLE = (
    "a JSON scene over HTTP has no bundle to read images from: send the scene as a USD bundle (a .zip with "
    "scene.usda and its images; textures in the materials' hg: attributes) or render it locally"
)


def scene_from_json(data: Any, options: JobOptions, limits: SceneLimits) -> Scene:
    """A JSON scene (already parsed), the request's film overrides written in, validated once."""
    scene = validate_scene(override_film(data, **film_overrides(options)), limits)
    require_no_images(scene, NO_BUNDLE)
    return scene


def scene_from_upload(
    filename: str, content: bytes, options: JobOptions, limits: SceneLimits
) -> tuple[Scene, dict[str, bytes]]:
    """An uploaded scene file → (validated scene, bundle files to store beside it).

    ``.json`` is parsed as a scene (overrides written in, validated once); USD layers and bundles
    (``.usda/.usdc/.usd/.usdz/.zip``) go through the isolated USD importer (a separate process with memory
    and time limits).
    """
    name = Path(filename or "").name
    suffix = Path(name).suffix.lower()
    if suffix == ".json":
        document = load_scene_json(content, limits)
        return scene_from_json(document, options, limits), {}
    if suffix not in USD_SUFFIXES:
        raise SceneError.at("", f"scene file {name!r}: expected .json or one of {', '.join(USD_SUFFIXES)}")
    from schemas.usd_import import import_usd_isolated

    with tempfile.TemporaryDirectory(prefix="hgrender-upload-") as tmp:
        bundle_dir = Path(tmp) / "bundle"
        bundle_dir.mkdir()
        # A .zip is extracted into the (empty) bundle folder; a single layer lives inside it.
        upload_path = Path(tmp) / "upload.zip" if suffix == ".zip" else bundle_dir / f"scene{suffix}"
        upload_path.write_bytes(content)
        scene = import_usd_isolated(upload_path, bundle_dir, limits, limits.usd_timeout_s)
        files = {
            path.relative_to(bundle_dir).as_posix(): path.read_bytes()
            for path in sorted(bundle_dir.rglob("*"))
            if path.is_file()
        }
    return with_film_overrides(scene, limits, **film_overrides(options)), files
