"""Procedural shapes: geometry against closed forms, located errors, limits, USD, the renderer's frame."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hgcore.settings import SceneLimits
from schemas import SceneError, build, validate_scene
from schemas.procedural import generate_mesh, mesh_size
from schemas.scene import OpticalDiscShape, ShellShape

SHAPES: dict[str, dict[str, Any]] = {
    "shell": {
        "type": "shell",
        "center_m": [0.1, 0.2, 0.3],
        "semi_axes_m": [0.07, 0.03, 0.05],
        "rib_count": 8,
        "rib_depth": 0.05,
        "segment_count": 3,
        "segment_depth": 0.02,
        "segments_along": 24,
        "segments_around": 48,
    },
    "wavy_sheet": {
        "type": "wavy_sheet",
        "center_m": [0, 0, 0],
        "normal": [0, 1, 0],
        "up": [0, 0, -1],
        "width_m": 0.4,
        "height_m": 0.2,
        "pattern": "waves",
        "amplitude_m": 0.01,
        "wavelength_m": 0.1,
        "segments": 64,
    },
    "optical_disc": {
        "type": "optical_disc",
        "center_m": [0, 0.01, 0],
        "normal": [0, 1, 0],
        "segments_around": 64,
    },
    "backdrop": {
        "type": "backdrop",
        "floor_center_m": [0, 0, 0],
        "facing": [0, 0, 1],
        "width_m": 1.0,
        "depth_m": 0.6,
        "height_m": 0.5,
        "cove_radius_m": 0.1,
        "segments": 8,
    },
}


def scene_with(shape: dict[str, Any]) -> dict[str, Any]:
    scene = build.scene(
        "",
        camera=build.camera([0, 0.5, 1.0], [0, 0, 0]),
        materials={"m": {"type": "diffuse", "reflectance": 0.5}},
        shapes=[{"material": "m", **shape}],
        emitters=[build.sphere([0, 1, 0], 0.05, spectrum={"type": "d65"}, power_w=1.0)],
    )
    del scene["name"]  # the schema's default name
    return scene


def generated(name: str) -> Any:
    shape = validate_scene(scene_with(SHAPES[name])).shapes[0]
    return shape, generate_mesh(shape)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_winding_normals_and_sizes_agree(name: str) -> None:
    shape, mesh = generated(name)
    assert (len(mesh.vertices_m), len(mesh.triangles)) == mesh_size(shape)
    a, b, c = (mesh.vertices_m[mesh.triangles[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)
    nondegenerate = np.linalg.norm(face, axis=1) > 1e-14
    vertex_side = mesh.normals[mesh.triangles].sum(axis=1)
    # Counter-clockwise winding seen from the side the vertex normals point to.
    assert np.all(np.sum(face * vertex_side, axis=1)[nondegenerate] > 0)
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-12)
    assert mesh.uvs.min() >= 0.0 and mesh.uvs.max() <= 1.0


def test_shell_without_relief_is_the_ellipsoid_with_outward_normals() -> None:
    shape = ShellShape(
        type="shell",
        material="m",
        center_m=[0, 0, 0],
        semi_axes_m=[0.07, 0.03, 0.05],
        rib_count=0,
        rib_depth=0.0,
        segments_along=64,
        segments_around=128,
    )
    mesh = generate_mesh(shape)
    x, y, z = mesh.vertices_m.T
    np.testing.assert_allclose((x / 0.07) ** 2 + (y / 0.03) ** 2 + (z / 0.05) ** 2, 1.0, atol=1e-12)
    gradient = np.stack([x / 0.07**2, y / 0.03**2, z / 0.05**2], axis=1)  # the ellipsoid's exact normal
    gradient /= np.linalg.norm(gradient, axis=1, keepdims=True)
    cosines = np.sum(gradient * mesh.normals, axis=1).reshape(65, 129)
    # Averaged face normals of a 64×128 grid: within 2 mrad away from the tips (where the curvature changes
    # within a cell); near the tips (thin triangles) within two grid steps of θ.
    assert cosines[8:-8].min() > math.cos(0.002)
    assert cosines.min() > math.cos(2 * math.pi / 64)


def test_wavy_sheet_heights_and_normals_follow_the_closed_form() -> None:
    _, mesh = generated("wavy_sheet")
    x, height, _ = mesh.vertices_m.T
    k = 2 * math.pi / 0.1
    np.testing.assert_allclose(height, 0.01 * np.sin(k * x), atol=1e-12)
    expected = np.stack([-0.01 * k * np.cos(k * x), np.ones_like(x), np.zeros_like(x)], axis=1)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(mesh.normals, expected, atol=1e-12)


def test_optical_disc_is_an_annulus_with_radial_u() -> None:
    _, mesh = generated("optical_disc")
    radius = np.hypot(mesh.vertices_m[:, 0], mesh.vertices_m[:, 2])
    assert radius.min() == pytest.approx(0.0075) and radius.max() == pytest.approx(0.06)
    np.testing.assert_allclose(mesh.uvs[:, 0], (radius - 0.0075) / (0.06 - 0.0075), atol=1e-12)
    np.testing.assert_allclose(mesh.vertices_m[:, 1], 0.01)


def test_backdrop_floor_cove_and_wall() -> None:
    _, mesh = generated("backdrop")
    floor = mesh.normals[:, 1] > 0.999
    wall = mesh.normals[:, 2] > 0.999
    np.testing.assert_allclose(mesh.vertices_m[floor, 1], 0.0, atol=1e-12)
    assert mesh.vertices_m[:, 1].max() == pytest.approx(0.5)
    np.testing.assert_allclose(mesh.vertices_m[wall, 2], -0.3 - 0.1, atol=1e-12)  # behind floor and cove
    assert mesh.vertices_m[:, 2].max() == pytest.approx(0.3)


@pytest.mark.parametrize(
    ("name", "change", "pointer", "message"),
    [
        ("shell", {"semi_axes_m": [0.1, 0, 0.1]}, "/shapes/0/semi_axes_m/1", "greater than 0"),
        ("shell", {"rib_depth": 0.3, "segment_depth": 0.25}, "/shapes/0", "would fold"),
        ("shell", {"axis": [0, 2, 0]}, "/shapes/0", "up must not be parallel to axis"),
        ("shell", {"segments_around": 5000}, "/shapes/0/segments_around", "less than or equal to 1024"),
        ("wavy_sheet", {"pattern": "zigzag"}, "/shapes/0/pattern", "waves"),
        ("wavy_sheet", {"wavelength_m": -1.0}, "/shapes/0/wavelength_m", "greater than 0"),
        ("optical_disc", {"inner_radius_m": 0.07}, "/shapes/0", "inner_radius_m must be smaller"),
        ("backdrop", {"cove_radius_m": 0.6}, "/shapes/0", "cove_radius_m must be smaller than height_m"),
        ("backdrop", {"facing": [0, 1, 0]}, "/shapes/0", "facing must not be parallel to up"),
    ],
)
def test_bad_parameters_name_the_field(name: str, change: dict[str, Any], pointer: str, message: str) -> None:
    with pytest.raises(SceneError) as error:
        validate_scene(scene_with({**SHAPES[name], **change}))
    problem = error.value.problems[0]
    assert problem["pointer"] == pointer
    assert message in problem["message"]


def test_generated_triangles_count_against_the_limits() -> None:
    shape = {**SHAPES["shell"], "segments_along": 100, "segments_around": 100}  # 20 000 triangles
    validate_scene(scene_with(shape), SceneLimits(max_triangles=20_000))
    with pytest.raises(SceneError, match="triangle count 20000 exceeds the limit of 19999"):
        validate_scene(scene_with(shape), SceneLimits(max_triangles=19_999))


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_usd_round_trip_and_standard_mesh(name: str, tmp_path: Path) -> None:
    from pxr import Usd, UsdGeom

    from schemas.usd_export import scene_to_usd
    from schemas.usd_import import import_usd

    scene = validate_scene(scene_with(SHAPES[name]))
    path = scene_to_usd(scene, tmp_path / "scene.usda")
    assert import_usd(path) == scene
    stage = Usd.Stage.Open(str(path))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Shapes/shape_0000"))
    _, generated_mesh = generated(name)
    np.testing.assert_allclose(np.asarray(mesh.GetPointsAttr().Get()), generated_mesh.vertices_m, atol=1e-6)
    assert len(mesh.GetFaceVertexCountsAttr().Get()) == len(generated_mesh.triangles)


def test_renderer_tangent_on_the_optical_disc_is_radial() -> None:
    """A grating's vector follows the first shading tangent: radial on the disc = concentric tracks."""
    from worker.mitsuba_setup import configured_mitsuba
    from worker.render.scene_compiler import SceneCompiler

    mi = configured_mitsuba()
    shape = OpticalDiscShape(type="optical_disc", material="m", center_m=[0, 0, 0], normal=[0, 1, 0])
    scene = mi.load_dict(
        {"type": "scene", "disc": SceneCompiler(mi, limits=SceneLimits())._shape_dict(shape)}
    )
    angles = np.linspace(0.1, 2 * math.pi, 7)
    for angle in angles:
        x, z = 0.03 * math.cos(angle), 0.03 * math.sin(angle)
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(x, 1.0, z), mi.Vector3f(0, -1, 0)))
        tangent = np.array(si.sh_frame.s).ravel()
        # Triangles span 0.5° of arc: the tangent is radial to within that.
        assert abs(np.dot(tangent, [math.cos(angle), 0.0, math.sin(angle)])) > math.cos(math.radians(0.5))
