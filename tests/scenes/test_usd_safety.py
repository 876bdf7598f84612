"""Hostile USD/bundles: each case ends in a located SceneError from the isolated importer, in bounded time.

Each import runs in a child process (``import_usd_isolated``); ``timeout_s`` bounds every call, and pytest's
per-test timeout bounds the test.
"""

from __future__ import annotations

import json
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pxr import Sdf, Usd, UsdGeom, UsdShade

from hgcore.settings import SceneLimits
from schemas import EXAMPLES_DIR, Scene, SceneError, validate_scene
from schemas.mesh_files import load_scene_meshes, read_mesh_file
from schemas.usd_export import scene_to_usd
from schemas.usd_import import import_usd_isolated

TIMEOUT_S = 60.0


def example_scene() -> Scene:
    return validate_scene(json.loads((EXAMPLES_DIR / "thin_film_sphere_light.json").read_text()))


def exported_bundle(directory: Path, name: str = "scene.usda") -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    return scene_to_usd(example_scene(), directory / name)


def isolated_error(path: Path, bundle: Path | None = None, **limit_overrides: int) -> SceneError:
    started = time.monotonic()
    with pytest.raises(SceneError) as caught:
        import_usd_isolated(path, bundle, SceneLimits(**limit_overrides), timeout_s=TIMEOUT_S)
    assert time.monotonic() - started < TIMEOUT_S
    problems = caught.value.problems
    assert problems and all(p["pointer"] and p["message"] for p in problems)
    return caught.value


def add_reference(path: Path, prim_path: str, asset_path: str) -> None:
    stage = Usd.Stage.Open(str(path))
    prim = UsdGeom.Xform.Define(stage, prim_path).GetPrim()
    prim.GetReferences().AddReference(asset_path)
    stage.Save()


@pytest.mark.parametrize(
    "asset_path",
    [
        "/etc/hostname",
        "../outside.usda",
        "sub/../../outside.usda",
        "http://example.com/x.usda",
        "file:///etc/x.usda",
    ],
)
def test_reference_escapes_are_rejected_with_the_prim_path(tmp_path: Path, asset_path: str) -> None:
    (tmp_path / "outside.usda").write_text("#usda 1.0\n")
    bundle = tmp_path / "bundle"
    scene_path = exported_bundle(bundle)
    add_reference(scene_path, "/World/Evil", asset_path)
    error = isolated_error(scene_path, bundle)
    assert error.problems[0]["pointer"] == "scene.usda</World/Evil>"


def test_payload_sublayer_and_texture_escapes_are_rejected(tmp_path: Path) -> None:
    bundle = tmp_path / "bundle"
    scene_path = exported_bundle(bundle)
    stage = Usd.Stage.Open(str(scene_path))
    stage.DefinePrim("/World/Heavy").GetPayloads().AddPayload("/tmp/elsewhere.usdc")
    stage.Save()
    error = isolated_error(scene_path, bundle)
    assert error.problems[0]["pointer"] == "scene.usda</World/Heavy>"
    assert "must be relative to the bundle, not absolute" in error.problems[0]["message"]

    scene_path = exported_bundle(tmp_path / "bundle2")
    layer = Sdf.Layer.FindOrOpen(str(scene_path))
    layer.subLayerPaths.append("../../secrets.usda")
    layer.Save()
    assert isolated_error(scene_path).problems[0]["pointer"] == "scene.usda subLayers"

    scene_path = exported_bundle(tmp_path / "bundle3")
    stage = Usd.Stage.Open(str(scene_path))
    texture = UsdShade.Shader.Define(stage, "/World/Materials/coated_silver/Texture")
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("/etc/passwd"))
    stage.Save()
    error = isolated_error(scene_path)
    assert error.problems[0]["pointer"] == "scene.usda</World/Materials/coated_silver/Texture>.inputs:file"

    scene_path = exported_bundle(tmp_path / "bundle4")
    stage = Usd.Stage.Open(str(scene_path))
    Usd.ClipsAPI(stage.DefinePrim("/World/Clipped")).SetClipAssetPaths([Sdf.AssetPath("/etc/x.usda")])
    stage.Save()
    error = isolated_error(scene_path)
    assert error.problems == [
        {
            "pointer": "scene.usda</World/Clipped>",
            "message": "value clips are not supported in uploaded scenes",
        }
    ]


def test_symlink_out_of_the_bundle_is_rejected(tmp_path: Path) -> None:
    (tmp_path / "outside.usda").write_text('#usda 1.0\ndef Xform "X" {}\n')
    bundle = tmp_path / "bundle"
    scene_path = exported_bundle(bundle)
    (bundle / "link.usda").symlink_to(tmp_path / "outside.usda")
    add_reference(scene_path, "/World/Linked", "./link.usda")
    assert "outside the bundle" in isolated_error(scene_path, bundle).problems[0]["message"]


def test_recursive_references_terminate(tmp_path: Path) -> None:
    bundle = tmp_path / "bundle"
    scene_path = exported_bundle(bundle)
    for name, other in (("a.usda", "b.usda"), ("b.usda", "a.usda")):
        (bundle / name).write_text(
            f'#usda 1.0\n(defaultPrim = "P")\ndef Xform "P" (references = @./{other}@) {{}}\n'
        )
    add_reference(scene_path, "/World/Loop", "./a.usda")
    add_reference(scene_path, "/World/Self", "./scene.usda")
    started = time.monotonic()
    try:
        scene = import_usd_isolated(scene_path, bundle, timeout_s=TIMEOUT_S)
    except SceneError as error:  # USD reports the cycle; either outcome is fine, a hang or crash is not
        assert error.problems
    else:
        assert scene.emitters
    assert time.monotonic() - started < TIMEOUT_S


def test_prim_and_triangle_limits(tmp_path: Path) -> None:
    bundle = tmp_path / "bundle"
    scene_path = exported_bundle(bundle)
    stage = Usd.Stage.Open(str(scene_path))
    for index in range(60):
        UsdGeom.Xform.Define(stage, f"/World/Empty{index}")
    mesh = UsdGeom.Mesh.Define(stage, "/World/Big")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([3] * 500)
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2] * 500)
    stage.Save()
    assert (
        "HGRENDER_MAX_USD_PRIMS"
        in isolated_error(scene_path, bundle, max_usd_prims=50).problems[0]["message"]
    )
    error = isolated_error(scene_path, bundle, max_triangles=100)
    assert error.problems[0]["pointer"] == "</World/Big>"
    assert "HGRENDER_MAX_TRIANGLES" in error.problems[0]["message"]
    assert (
        "HGRENDER_MAX_FILE_BYTES"
        in isolated_error(scene_path, bundle, max_file_bytes=1000).problems[0]["message"]
    )
    assert "HGRENDER_MAX_SPP" in str(isolated_error(scene_path, bundle, max_spp=8))


def test_timeout_and_parser_crash_become_scene_errors(tmp_path: Path) -> None:
    scene_path = exported_bundle(tmp_path / "bundle")
    with pytest.raises(SceneError, match=r"timed out after 0\.05 s"):
        import_usd_isolated(scene_path, timeout_s=0.05)
    # 64 MiB of address space cannot even load the USD libraries: the child dies, the caller gets an error.
    with pytest.raises(
        SceneError, match=r"^bundle:scene.usda: (the USD parser (crashed|failed)|out of resources)"
    ):
        import_usd_isolated(
            scene_path, limits=SceneLimits(max_usd_memory_bytes=64 * 1024 * 1024), timeout_s=TIMEOUT_S
        )


def test_corrupt_usdc_is_a_scene_error(tmp_path: Path) -> None:
    scene_path = exported_bundle(tmp_path / "bundle", "scene.usdc")
    data = scene_path.read_bytes()
    scene_path.write_bytes(data[: len(data) // 2])
    assert "cannot read USD layer" in isolated_error(scene_path).problems[0]["message"]
    scene_path.write_bytes(b"PXR-USDC" + b"\xff" * 200)
    isolated_error(scene_path)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_usdc_bytes_never_escape_as_crashes(tmp_path: Path, data: st.DataObject) -> None:
    """Random byte overwrites of a valid crate file: a Scene (harmless change) or a SceneError, never more."""
    directory = tmp_path / f"case{data.draw(st.integers(0, 10**9))}"
    scene_path = exported_bundle(directory, "scene.usdc")
    content = bytearray(scene_path.read_bytes())
    for _ in range(data.draw(st.integers(1, 8))):
        position = data.draw(st.integers(0, len(content) - 1))
        content[position] = data.draw(st.integers(0, 255))
    scene_path.write_bytes(bytes(content))
    try:
        scene = import_usd_isolated(scene_path, timeout_s=TIMEOUT_S)
    except SceneError as error:
        assert error.problems[0]["pointer"] and error.problems[0]["message"]
    else:
        assert scene.emitters


def _zip_directory(directory: Path, zip_path: Path, extra: dict[str, bytes] | None = None) -> Path:
    with zipfile.ZipFile(zip_path, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(directory.rglob("*")):
            if file.is_file():
                archive.write(file, file.relative_to(directory).as_posix())
        for name, content in (extra or {}).items():
            archive.writestr(name, content)
    return zip_path


def test_zip_bundles(tmp_path: Path) -> None:
    source = tmp_path / "source"
    exported_bundle(source)
    good = _zip_directory(source, tmp_path / "good.zip")
    extracted = tmp_path / "extracted"
    assert import_usd_isolated(good, extracted, timeout_s=TIMEOUT_S) == example_scene()
    assert (extracted / "scene.usda").is_file()

    truncated = tmp_path / "truncated.zip"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    assert "zip" in isolated_error(truncated).problems[0]["message"]

    evil = _zip_directory(source, tmp_path / "evil.zip", {"../escape.usda": b"#usda 1.0\n"})
    assert isolated_error(evil).problems[0]["pointer"] == "bundle:../escape.usda"

    bomb = _zip_directory(source, tmp_path / "bomb.zip", {"padding.bin": b"\0" * 2_000_000})
    error = isolated_error(bomb, None, max_file_bytes=1_000_000)
    assert error.problems[0]["pointer"] == "bundle:padding.bin"


def test_mesh_files_in_bundles(tmp_path: Path) -> None:
    limits = SceneLimits()
    (tmp_path / "quad.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\nf -4 -3 -2\n"
    )
    mesh = read_mesh_file(tmp_path, "quad.obj", limits, "/shapes/0/path")
    assert mesh.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 2]]
    header = "ply\nformat {}\nelement vertex 4\nproperty float x\nproperty float y\nproperty double z\n"
    header += "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    (tmp_path / "quad_ascii.ply").write_text(
        header.format("ascii 1.0") + "0 0 0\n1 0 0\n1 1 0\n0 1 0.5\n4 0 1 2 3\n"
    )
    vertex = np.array(
        [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0.5)], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f8")]
    )
    face = np.array([4], dtype="u1").tobytes() + np.array([0, 1, 2, 3], dtype="<i4").tobytes()
    (tmp_path / "quad_binary.ply").write_bytes(
        header.format("binary_little_endian 1.0").encode() + vertex.tobytes() + face
    )
    for name in ("quad_ascii.ply", "quad_binary.ply"):
        ply = read_mesh_file(tmp_path, name, limits, "/shapes/0/path")
        assert ply.triangles.tolist() == [[0, 1, 2], [0, 2, 3]]
        assert ply.vertices_m[3].tolist() == [0.0, 1.0, 0.5]
    (tmp_path / "cut.ply").write_bytes((tmp_path / "quad_binary.ply").read_bytes()[:-6])
    with pytest.raises(SceneError, match=r"^/shapes/0/path: malformed or truncated PLY"):
        read_mesh_file(tmp_path, "cut.ply", limits, "/shapes/0/path")
    with pytest.raises(SceneError, match="HGRENDER_MAX_TRIANGLES"):
        read_mesh_file(tmp_path, "quad.obj", SceneLimits(max_triangles=2), "/shapes/0/path")

    data = json.loads((EXAMPLES_DIR / "thin_film_sphere_light.json").read_text())
    data["shapes"].append({"type": "mesh_file", "material": "floor", "path": "missing.obj"})
    scene = validate_scene(data)
    with pytest.raises(SceneError, match=r"^/shapes/2/path: path 'missing.obj' is not a file"):
        load_scene_meshes(scene, tmp_path, limits)
    data["shapes"][-1]["path"] = "../quad.obj"
    with pytest.raises(SceneError, match=r"^/shapes/2/path: path must stay inside the bundle"):
        validate_scene(data)
