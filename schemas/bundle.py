"""Uploaded scene bundles: safe zip extraction and confinement of every USD asset path to the bundle.

A bundle is a directory (or a zip of one) holding a root scene file plus the files it refers to: USD
sublayers, references, payloads and textures, and OBJ/PLY meshes. Every asset path must be relative, free
of ``..``, not a URL, and resolve (symlinks followed) inside the bundle directory; anything else is a
:class:`SceneError` naming the layer and prim path that mentions it. Sizes and counts follow
:class:`SceneLimits`. These checks run *before* a USD stage is composed, so composition never touches
anything outside the bundle.
"""

from __future__ import annotations

import stat
import zipfile
from collections import deque
from pathlib import Path

from pxr import Sdf, Tf

from hgcore.errors import InputError
from hgcore.settings import SceneLimits
from schemas.errors import SceneError, without_paths
from schemas.scene import check_bundle_relative_path

USD_LAYER_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
ROOT_LAYER_NAMES = ("scene.usda", "scene.usdc", "scene.usd", "scene.usdz")
_COPY_CHUNK_BYTES = 1 << 20


def is_inside(path: Path, directory: Path) -> bool:
    """Whether ``path`` resolves (symlinks followed) to ``directory`` or something below it."""
    return path.resolve().is_relative_to(directory.resolve())


def extract_zip_bundle(zip_path: Path, destination: Path, limits: SceneLimits) -> Path:
    """Extract ``zip_path`` into the empty directory ``destination``; return the root scene file.

    Rejects: unreadable or truncated archives, member names that are absolute or contain ``..``,
    symlinks, more than ``max_bundle_files`` members, any member over ``max_file_bytes`` and a total over
    ``max_bundle_bytes`` — counted while decompressing, so a lying header cannot produce a zip bomb.
    """
    where = f"bundle:{zip_path.name}"
    if zip_path.stat().st_size > limits.max_bundle_bytes:
        raise SceneError.at(where, f"archive exceeds the limit of {limits.max_bundle_bytes} bytes")
    destination.mkdir(parents=True, exist_ok=True)
    if any(destination.iterdir()):
        raise InputError(f"destination: {destination} must be empty")
    total_bytes = 0
    try:
        with zipfile.ZipFile(zip_path) as archive:
            members = archive.infolist()
            if len(members) > limits.max_bundle_files:
                raise SceneError.at(
                    where,
                    f"{len(members)} files exceed the limit of {limits.max_bundle_files} "
                    "(HGRENDER_MAX_BUNDLE_FILES)",
                )
            for member in members:
                name = member.filename
                member_where = f"bundle:{name}"
                try:
                    check_bundle_relative_path(name.rstrip("/"))
                except ValueError as error:
                    raise SceneError.at(member_where, str(error)) from None
                if stat.S_ISLNK(member.external_attr >> 16):
                    raise SceneError.at(member_where, "symbolic links are not allowed in a bundle")
                target = destination / name
                if member.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                if member.file_size > limits.max_file_bytes:
                    raise SceneError.at(
                        member_where, f"{member.file_size} bytes exceed the limit of {limits.max_file_bytes}"
                    )
                target.parent.mkdir(parents=True, exist_ok=True)
                written = 0
                with archive.open(member) as source, open(target, "xb") as sink:
                    while chunk := source.read(_COPY_CHUNK_BYTES):
                        written += len(chunk)
                        total_bytes += len(chunk)
                        if written > limits.max_file_bytes or total_bytes > limits.max_bundle_bytes:
                            raise SceneError.at(
                                member_where,
                                "decompressed size exceeds the bundle limits (HGRENDER_MAX_FILE_BYTES / "
                                "HGRENDER_MAX_BUNDLE_BYTES)",
                            )
                        sink.write(chunk)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, NotImplementedError) as error:
        raise SceneError.at(where, f"not a readable zip archive: {error}") from None
    return find_root_layer(destination)


def find_root_layer(bundle_dir: Path) -> Path:
    """The bundle's root USD file: ``scene.usd[a|c|z]`` if present, else the only top-level USD file."""
    for name in ROOT_LAYER_NAMES:
        if (bundle_dir / name).is_file():
            return bundle_dir / name
    candidates = sorted(
        p for p in bundle_dir.iterdir() if p.is_file() and p.suffix.lower() in USD_LAYER_SUFFIXES
    )
    if len(candidates) != 1:
        found = ", ".join(p.name for p in candidates) or "none"
        raise SceneError.at(
            f"bundle:{bundle_dir.name}",
            f"cannot tell the root scene file: name it scene.usda (top-level USD files found: {found})",
        )
    return candidates[0]


def check_asset_path(asset_path: str, anchor_layer: Sdf.Layer, bundle_dir: Path, where: str) -> str:
    """Check one asset path mentioned at ``where``; return its absolute identifier (package-aware)."""
    if Sdf.Layer.IsAnonymousLayerIdentifier(asset_path):
        raise SceneError.at(where, f"asset path {asset_path!r} refers to an anonymous layer")
    try:
        check_bundle_relative_path(asset_path.removeprefix("./"))
    except ValueError as error:
        raise SceneError.at(where, f"asset {error}") from None
    identifier = anchor_layer.ComputeAbsolutePath(asset_path)
    outer_file = Path(identifier.split("[", 1)[0])
    if not is_inside(outer_file, bundle_dir):
        raise SceneError.at(where, f"asset path {asset_path!r} resolves outside the bundle")
    return identifier


def _layer_where(layer: Sdf.Layer, bundle_dir: Path, spec_path: Sdf.Path | None = None) -> str:
    real_path = Path(layer.realPath or layer.identifier)
    try:
        layer_name = real_path.resolve().relative_to(bundle_dir.resolve()).as_posix()
    except ValueError:
        layer_name = real_path.name
    return f"{layer_name}<{spec_path}>" if spec_path is not None else layer_name


def _open_layer(identifier: str, bundle_dir: Path, limits: SceneLimits, where: str) -> Sdf.Layer:
    outer_file = Path(identifier.split("[", 1)[0])
    if not outer_file.is_file():
        raise SceneError.at(where, f"asset {outer_file.name!r} is not a file in the bundle")
    if outer_file.stat().st_size > limits.max_file_bytes:
        raise SceneError.at(
            where,
            f"{outer_file.name} exceeds the limit of {limits.max_file_bytes} bytes (HGRENDER_MAX_FILE_BYTES)",
        )
    try:
        layer = Sdf.Layer.FindOrOpen(identifier)
    except Tf.ErrorException as error:
        detail = without_paths(str(error).strip().splitlines()[-1]) if str(error).strip() else "unreadable"
        raise SceneError.at(where, f"cannot read USD layer {outer_file.name}: {detail}") from None
    if layer is None:
        raise SceneError.at(where, f"cannot read USD layer {outer_file.name}")
    return layer


def check_usd_layers(root_file: Path, bundle_dir: Path, limits: SceneLimits) -> list[Sdf.Layer]:
    """Open the root layer and every layer it reaches, checking all asset paths; return the layers.

    Walks sublayers, references and payloads (including those inside variants) breadth-first with a
    visited set, so recursive references terminate; asset-valued attributes (textures) are checked but
    not opened. Total size of opened layers is bounded by ``max_bundle_bytes``.
    """
    if not is_inside(root_file, bundle_dir):
        raise SceneError.at(
            f"bundle:{root_file.name}", "the root scene file must be inside the bundle directory"
        )
    root_where = f"bundle:{root_file.name}"
    root_layer = _open_layer(str(root_file.resolve()), bundle_dir, limits, root_where)
    layers = [root_layer]
    queue: deque[Sdf.Layer] = deque([root_layer])
    seen: set[str] = {root_layer.identifier}
    total_bytes = root_file.stat().st_size
    spec_budget = [limits.max_usd_prims * 64]  # properties and prims of all layers together

    while queue:
        layer = queue.popleft()
        pending: list[tuple[str, str]] = []  # (asset path, where) to open as layers

        for sublayer in layer.subLayerPaths:
            pending.append((sublayer, f"{_layer_where(layer, bundle_dir)} subLayers"))

        def visit(path: Sdf.Path, layer: Sdf.Layer = layer, pending: list[tuple[str, str]] = pending) -> None:
            spec_budget[0] -= 1
            if spec_budget[0] < 0:
                raise SceneError.at(
                    _layer_where(layer, bundle_dir), "too many prims/properties (HGRENDER_MAX_USD_PRIMS)"
                )
            if path.IsPrimPath() or path.IsPrimVariantSelectionPath():
                prim_spec = layer.GetPrimAtPath(path)
                if prim_spec is None:
                    return
                where = _layer_where(layer, bundle_dir, path)
                # Value clips name further layers in prim metadata; refuse them rather than track them.
                if any(prim_spec.HasInfo(key) for key in ("clips", "clipSets")):
                    raise SceneError.at(where, "value clips are not supported in uploaded scenes")
                for arc in (
                    *prim_spec.referenceList.GetAddedOrExplicitItems(),
                    *prim_spec.payloadList.GetAddedOrExplicitItems(),
                ):
                    if arc.assetPath:
                        pending.append((arc.assetPath, where))
            elif path.IsPropertyPath():
                attribute_spec = layer.GetAttributeAtPath(path)
                if attribute_spec is None or attribute_spec.typeName not in (
                    Sdf.ValueTypeNames.Asset,
                    Sdf.ValueTypeNames.AssetArray,
                ):
                    return
                where = _layer_where(layer, bundle_dir, path.GetPrimPath())
                values = [attribute_spec.default] if attribute_spec.HasDefaultValue() else []
                values += [layer.QueryTimeSample(path, time) for time in layer.ListTimeSamplesForPath(path)]
                for value in values:
                    for asset in [value] if isinstance(value, Sdf.AssetPath) else list(value or []):
                        if isinstance(asset, Sdf.AssetPath) and asset.path:
                            check_asset_path(asset.path, layer, bundle_dir, f"{where}.{path.name}")

        layer.Traverse(Sdf.Path.absoluteRootPath, visit)

        for asset_path, where in pending:
            identifier = check_asset_path(asset_path, layer, bundle_dir, where)
            if identifier in seen:
                continue
            seen.add(identifier)
            child = _open_layer(identifier, bundle_dir, limits, where)
            total_bytes += Path(identifier.split("[", 1)[0]).stat().st_size if "[" not in identifier else 0
            if total_bytes > limits.max_bundle_bytes or len(seen) > limits.max_bundle_files:
                raise SceneError.at(
                    where, "referenced layers exceed the bundle limits (HGRENDER_MAX_BUNDLE_*)"
                )
            layers.append(child)
            queue.append(child)
    return layers


def resolve_bundle_file(bundle_dir: Path, relative_path: str, where: str) -> Path:
    """The file at ``relative_path`` inside ``bundle_dir``; a SceneError if it escapes or is missing."""
    try:
        check_bundle_relative_path(relative_path)
    except ValueError as error:
        raise SceneError.at(where, str(error)) from None
    candidate = bundle_dir / relative_path
    if not is_inside(candidate, bundle_dir):
        raise SceneError.at(where, f"path {relative_path!r} resolves outside the bundle")
    if not candidate.is_file():
        raise SceneError.at(where, f"path {relative_path!r} is not a file in the bundle")
    return candidate
