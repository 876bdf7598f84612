"""USD export/import: exact round trips, a hand-authored stage, and the generic UsdGeom/UsdLux mapping."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

from hgcore.optics.spectra import cie_cmf, planck_radiance
from schemas import EXAMPLES_DIR, Scene, SceneError, validate_scene
from schemas.photometry import emitter_radiance_scale, luminance_per_radiance_scale
from schemas.scene import BlackbodySpectrum, MeshShape, RoughConductorMaterial, SphereShape, ThinFilmMaterial
from schemas.usd_export import scene_to_usd
from schemas.usd_import import import_usd, import_usd_isolated
from tests.support.images import write_image

EXAMPLE_PATHS = sorted(EXAMPLES_DIR.glob("*.json"))


def load_example(name: str) -> Scene:
    return validate_scene(json.loads((EXAMPLES_DIR / name).read_text()))


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usdz"])
@pytest.mark.parametrize("path", EXAMPLE_PATHS, ids=lambda path: path.name)
def test_json_to_usd_to_json_is_equal(path: Path, suffix: str, tmp_path: Path) -> None:
    scene = validate_scene(json.loads(path.read_text()))
    usd_path = scene_to_usd(scene, tmp_path / f"scene{suffix}")
    assert import_usd(usd_path) == scene


def test_round_trip_covers_every_shape_transform_and_camera_form(tmp_path: Path) -> None:
    data = json.loads((EXAMPLES_DIR / "cornell_box.json").read_text())
    data["name"] = "all forms: ünïcode"
    data["camera"] = {
        "to_world": [[-1, 0, 0, 0.1], [0, 1, 0, 0.2], [0, 0, -1, 3.0], [0, 0, 0, 1]],
        "focal_length_mm": 35.0,
        "sensor_width_mm": 24.0,
        "near_clip_m": 0.01,
        "aperture_radius_m": 0.004,
        "focus_distance_m": 2.5,
    }
    data["film"] = {"width": 40, "height": 24, "bands": 8, "wavelength_min_nm": 400.5, "seed": 7, "modes": 4}
    data["materials"] |= {
        "glass.1": {"type": "dielectric", "ior": "bk7"},
        "grating-2d": {"type": "grating", "pitch_um": 1.1, "pitch_y_um": 0.9, "orientation_deg": 30.0},
        "film_on_glass": {
            "type": "thin_film",
            "film_thickness_um": 0.4,
            "film_ior": "water",
            "substrate": {"ior": 1.52},
            "psd": "abc",
            "psd_exponent": 3.5,
            "beams": 2,
        },
        "rough_glass": {
            "type": "rough_dielectric",
            "ior": 1.33,
            "roughness_rms_um": 0.2,
            "correlation_length_um": 2.0,
        },
    }
    data["shapes"] += [
        {
            "type": "cylinder",
            "material": "glass.1",
            "p0_m": [0, -1, 0],
            "p1_m": [0.1, 0.5, 0.2],
            "radius_m": 0.05,
        },
        {
            "type": "disk",
            "material": "grating-2d",
            "center_m": [0.3, 0, 0],
            "normal": [1, 1, 0],
            "radius_m": 0.2,
        },
        {
            "type": "sphere",
            "material": "film_on_glass",
            "center_m": [0.1, 0.2, 0.3],
            "radius_m": 0.1,
            "transform": {"matrix": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5], [0, 0, 0, 1]]},
        },
        {
            "type": "mesh",
            "material": "rough_glass",
            "vertices_m": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            "indices": [[0, 1, 2]],
            "normals": [[0, 0, 1], [0, 0, 1], [0, 0, 1]],
            "transform": {"scale": [1.0, 2.0, 3.0], "rotate_axis": [0, 0, 1], "rotate_deg": 10.0},
        },
        {"type": "mesh_file", "material": "white", "path": "meshes/bunny.ply"},
    ]
    data["emitters"] += [
        {
            "type": "disk",
            "center_m": [0, 0.5, 0],
            "normal": [0, -1, 0],
            "radius_m": 0.1,
            "spectrum": {"type": "blackbody", "temperature_k": 2700.0},
            "radiance_scale": 1e-3,
        },
        {
            "type": "cylinder",
            "p0_m": [0, 0, 0],
            "p1_m": [0, 0.3, 0],
            "radius_m": 0.01,
            "spectrum": {"type": "cie_f", "name": "F7"},
            "power_w": 3.0,
        },
    ]
    scene = validate_scene(data)
    usd_path = scene_to_usd(scene, tmp_path / "all.usda")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "bunny.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    assert import_usd(usd_path) == scene
    # The same file through the isolated child process.
    assert import_usd_isolated(usd_path, timeout_s=60) == scene


def _strip_hg_geometry(usd_path: Path) -> None:
    """Remove the hg: mirror from cameras, shapes and lights so only standard USD data is left."""
    stage = Usd.Stage.Open(str(usd_path))
    for prim in stage.Traverse():
        if prim.IsA(UsdShade.Material) or prim.IsA(UsdShade.Shader):
            continue
        for attribute in prim.GetAuthoredAttributes():
            if attribute.GetName().startswith("hg:"):
                prim.RemoveProperty(attribute.GetName())
    stage.Save()


def test_standard_usd_data_alone_reproduces_geometry_light_and_camera(tmp_path: Path) -> None:
    """The UsdGeom/UsdLux data the exporter writes means the same scene to the generic importer.

    Tolerances: USD stores points, light sizes, intensities and lens values as float32, so values agree
    to a few float32 ulps (relative 1e-6); positions built from double matrices agree to 1e-6 m.
    """
    scene = load_example("thin_film_cylinder_light.json")
    # A thin lens focused on the target (fStop = f/(2a), focusDistance in scene units).
    scene = scene.model_copy(update={"camera": scene.camera.model_copy(update={"aperture_radius_m": 0.01})})
    usd_path = scene_to_usd(scene, tmp_path / "generic.usda")
    _strip_hg_geometry(usd_path)
    imported = import_usd(usd_path)
    assert imported.camera.horizontal_fov_deg() == pytest.approx(scene.camera.horizontal_fov_deg(), rel=1e-6)
    assert imported.camera.origin_m == pytest.approx(scene.camera.origin_m, abs=1e-6)
    assert imported.camera.aperture_radius_m == pytest.approx(0.01, rel=1e-6)
    assert imported.camera.focus_distance() == pytest.approx(scene.camera.focus_distance(), rel=1e-6)
    sphere, floor = imported.shapes
    assert isinstance(sphere, SphereShape)
    assert sphere.center_m == pytest.approx([0, 0, 0], abs=1e-9)
    assert sphere.radius_m == pytest.approx(0.05, rel=1e-12)
    assert isinstance(floor, MeshShape)
    assert np.ptp(np.asarray(floor.vertices_m), axis=0) == pytest.approx([1.0, 0.0, 1.0], abs=1e-6)
    (light,) = imported.emitters
    (original,) = scene.emitters
    assert light.type == "cylinder"
    assert np.sort([light.p0_m, light.p1_m], axis=0) == pytest.approx(
        np.sort([original.p0_m, original.p1_m], axis=0), abs=1e-6
    )
    assert light.radius_m == pytest.approx(original.radius_m, rel=1e-6)
    # Luminance is what UsdLux carries: the exported intensity gives back the same luminance (nits).
    film = scene.film
    original_nits = emitter_radiance_scale(original, film.wavelength_min_nm, film.wavelength_max_nm) * (
        luminance_per_radiance_scale(original.spectrum)
    )
    imported_nits = light.radiance_scale * luminance_per_radiance_scale(light.spectrum)
    assert imported_nits == pytest.approx(original_nits, rel=1e-6)
    # Materials keep their hg: attributes, so they come back exactly.
    assert imported.materials == scene.materials


def _author_test_stage(bundle: Path) -> Path:
    """Z-up stage in centimetres: instanced mesh asset, camera, CylinderLight, hg: material, preview gold."""
    asset = Usd.Stage.CreateNew(str(bundle / "tile.usda"))
    UsdGeom.SetStageUpAxis(asset, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(asset, 0.01)
    tile = UsdGeom.Xform.Define(asset, "/Tile")
    asset.SetDefaultPrim(tile.GetPrim())
    quad = UsdGeom.Mesh.Define(asset, "/Tile/Quad")
    quad.CreatePointsAttr([(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0)])
    quad.CreateFaceVertexCountsAttr([4])
    quad.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    asset.Save()

    stage = Usd.Stage.CreateNew(str(bundle / "scene.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetMetadata(
        "customLayerData", {"hgrender": {"name": "authored", "film": {"width": 32, "height": 16, "spp": 4}}}
    )
    UsdGeom.Xform.Define(stage, "/World")

    coated = UsdShade.Material.Define(stage, "/World/Looks/Coated")
    for name, type_name, value in [
        ("hg:type", Sdf.ValueTypeNames.Token, "thin_film"),
        ("hg:filmThicknessUm", Sdf.ValueTypeNames.Double, 1.23),
        ("hg:filmIor", Sdf.ValueTypeNames.Double, 1.45),
        ("hg:substrate:conductor", Sdf.ValueTypeNames.Token, "Ag"),
        ("hg:psd", Sdf.ValueTypeNames.Token, "abc"),
        ("hg:psdExponent", Sdf.ValueTypeNames.Double, 2.5),
        ("hg:roughnessRmsUm", Sdf.ValueTypeNames.Double, 0.04),
        ("hg:correlationLengthUm", Sdf.ValueTypeNames.Double, 6.0),
        ("hg:scatteringRegionRadiusM", Sdf.ValueTypeNames.Double, 2e-3),
        ("hg:beams", Sdf.ValueTypeNames.Int, 3),
    ]:
        coated.GetPrim().CreateAttribute(name, type_name, custom=True).Set(value)
    gold = UsdShade.Material.Define(stage, "/World/Looks/Gold")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/Gold/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(1.0, 0.8, 0.35))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(1.0)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.5)
    gold.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")

    for index, offset_cm in enumerate((0.0, 20.0)):
        instance = UsdGeom.Xform.Define(stage, f"/World/Tile{index}")
        instance.GetPrim().GetReferences().AddReference("./tile.usda")
        instance.GetPrim().SetInstanceable(True)
        instance.AddTranslateOp().Set(Gf.Vec3d(offset_cm, 0.0, 0.0))
        UsdShade.MaterialBindingAPI.Apply(instance.GetPrim()).Bind(coated)

    ball = UsdGeom.Sphere.Define(stage, "/World/Ball")
    ball.CreateRadiusAttr(5.0)
    ball.AddTranslateOp().Set(Gf.Vec3d(10.0, 0.0, 0.0))
    ball.AddScaleOp().Set(Gf.Vec3f(2.0, 2.0, 2.0))
    UsdShade.MaterialBindingAPI.Apply(ball.GetPrim()).Bind(gold)

    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.AddTranslateOp().Set(Gf.Vec3d(0.0, -500.0, 100.0))
    camera.AddRotateXOp().Set(90.0)  # look along +Y (Z-up world), image up = +Z
    camera.CreateFocalLengthAttr(50.0)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateClippingRangeAttr(Gf.Vec2f(1.0, 100000.0))
    camera.CreateFStopAttr(2.0)
    camera.CreateFocusDistanceAttr(400.0)

    light = UsdLux.CylinderLight.Define(stage, "/World/Tube")
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 300.0))
    light.CreateLengthAttr(20.0)
    light.CreateRadiusAttr(0.1)
    light.CreateIntensityAttr(1000.0)
    light.CreateExposureAttr(1.0)
    light.CreateEnableColorTemperatureAttr(True)
    light.CreateColorTemperatureAttr(3000.0)
    stage.Save()
    return bundle / "scene.usda"


def test_authored_stage_imports_expected_values(tmp_path: Path) -> None:
    scene = import_usd_isolated(_author_test_stage(tmp_path), timeout_s=60)
    assert scene.name == "authored"
    assert (scene.film.width, scene.film.height, scene.film.spp) == (32, 16, 4)

    # Camera: Z-up centimetres → Y-up metres: (0, −500, 100) cm → (0, 1, 5) m, looking along −Z.
    camera = scene.camera
    assert camera.origin_m == pytest.approx([0.0, 1.0, 5.0], abs=1e-9)
    assert camera.target_m == pytest.approx([0.0, 1.0, 4.0], abs=1e-9)
    assert camera.up == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)
    # Lens values are tenths of a scene unit: 50 × (0.01 m / 10) = 50 mm.
    assert camera.focal_length_mm == pytest.approx(50.0, rel=1e-6)
    assert camera.sensor_width_mm == pytest.approx(36.0, rel=1e-6)
    assert (camera.near_clip_m, camera.far_clip_m) == pytest.approx((0.01, 1000.0), rel=1e-6)
    # f/2 at 50 mm: a lens of radius 50 mm / (2 × 2) = 12.5 mm, focused at 400 cm along the view axis.
    assert camera.aperture_radius_m == pytest.approx(0.0125, rel=1e-6)
    assert camera.focus_distance_m == pytest.approx(4.0, rel=1e-6)

    # Two instances of a referenced 10 cm quad, flattened and triangulated; shared hg: thin film.
    tiles = [shape for shape in scene.shapes if isinstance(shape, MeshShape)]
    assert len(tiles) == 2
    for tile, offset_m in zip(tiles, (0.0, 0.2), strict=True):
        assert len(tile.indices) == 2
        vertices = np.asarray(tile.vertices_m)
        assert vertices.min(axis=0) == pytest.approx([offset_m, 0.0, -0.1], abs=1e-9)
        assert vertices.max(axis=0) == pytest.approx([offset_m + 0.1, 0.0, 0.0], abs=1e-9)
    coated = scene.materials[tiles[0].material]
    assert tiles[1].material == tiles[0].material
    assert isinstance(coated, ThinFilmMaterial)
    assert (coated.film_thickness_um, coated.film_ior, coated.substrate.conductor) == (1.23, 1.45, "Ag")
    assert (coated.psd, coated.psd_exponent, coated.beams) == ("abc", 2.5, 3)
    assert (coated.roughness_rms_um, coated.correlation_length_um) == (0.04, 6.0)
    assert coated.scattering_region_radius_m == 2e-3

    # Sphere: radius 5 cm scaled ×2 → 0.1 m, centre (10, 0, 0) cm → (0.1, 0, 0) m.
    (ball,) = [shape for shape in scene.shapes if isinstance(shape, SphereShape)]
    assert ball.center_m == pytest.approx([0.1, 0.0, 0.0], abs=1e-9)
    assert ball.radius_m == pytest.approx(0.1, rel=1e-12)
    gold = scene.materials[ball.material]
    assert isinstance(gold, RoughConductorMaterial)
    assert gold.conductor == "Au"
    # σ = α ℓ/√2 with α = roughness² = 0.25 and ℓ = 5 µm.
    assert gold.roughness_rms_um == pytest.approx(0.25 * 5.0 / math.sqrt(2.0), rel=1e-12)

    # CylinderLight: 20 cm long along local X, radius 0.1 cm, at 3 m height.
    (tube,) = scene.emitters
    assert tube.type == "cylinder"
    assert tube.p0_m == pytest.approx([-0.1, 3.0, 0.0], abs=1e-9)
    assert tube.p1_m == pytest.approx([0.1, 3.0, 0.0], abs=1e-9)
    assert tube.radius_m == pytest.approx(0.001, rel=1e-6)
    assert tube.spectrum == BlackbodySpectrum(type="blackbody", temperature_k=3000.0)
    # UsdLux: intensity·2^exposure = 2000 nits of luminance = 683 · c · ∫ B_λ(3000 K) ȳ dλ. Computed here with
    # an independent 0.5 nm trapezoid rule (the importer uses 1 nm): both resolve the smooth integrand to
    # better than 1e-5 relative.
    wavelengths = np.arange(360.0, 830.0 + 0.25, 0.5)
    integral = np.trapezoid(planck_radiance(wavelengths, 3000.0) * cie_cmf(wavelengths)[:, 1], wavelengths)
    assert tube.radiance_scale == pytest.approx(2000.0 / (683.0 * integral), rel=1e-5)


def test_distant_light_is_rejected_with_its_prim_path(tmp_path: Path) -> None:
    stage_path = _author_test_stage(tmp_path)
    stage = Usd.Stage.Open(str(stage_path))
    UsdLux.DistantLight.Define(stage, "/World/Sun")
    stage.Save()
    with pytest.raises(SceneError) as caught:
        import_usd(stage_path)
    assert caught.value.problems[0]["pointer"] == "</World/Sun>"
    # Not mapped from UsdLux yet (issue 28); an hgrender sun (hg:type "sun") is what it would map onto.
    assert "DistantLight is not mapped yet" in caught.value.problems[0]["message"]
    assert 'hg:type "sun"' in caught.value.problems[0]["message"]


def test_thin_lens_without_focus_distance_is_rejected_with_its_prim_path(tmp_path: Path) -> None:
    stage_path = _author_test_stage(tmp_path)
    stage = Usd.Stage.Open(str(stage_path))
    UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetFocusDistanceAttr().Set(0.0)
    stage.Save()
    with pytest.raises(SceneError) as caught:
        import_usd(stage_path)
    assert caught.value.problems[0]["pointer"] == "</World/Camera>"
    assert "focusDistance" in caught.value.problems[0]["message"]


def test_invalid_hg_attribute_is_named(tmp_path: Path) -> None:
    stage_path = _author_test_stage(tmp_path)
    stage = Usd.Stage.Open(str(stage_path))
    stage.GetPrimAtPath("/World/Looks/Coated").GetAttribute("hg:filmThicknessUm").Set(-1.0)
    stage.Save()
    with pytest.raises(SceneError) as caught:
        import_usd(stage_path)
    assert caught.value.problems == [
        {"pointer": "</World/Looks/Coated>", "message": "hg:filmThicknessUm: Input should be greater than 0"}
    ]


def _strip_stage(bundle: Path) -> Path:
    """Two unit quads sharing an edge (6 points, 8 face corners) with faceVarying, indexed ``st`` (a seam:
    the shared edge has u = 1 on the left quad and u = 0 on the right) and a per-point ``uv2``."""
    stage = Usd.Stage.CreateNew(str(bundle / "scene.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/World")
    mesh = UsdGeom.Mesh.Define(stage, "/World/Strip")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4, 4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 4, 3, 1, 2, 5, 4])
    primvars = UsdGeom.PrimvarsAPI(mesh)
    st = primvars.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    st.SetIndices([0, 1, 2, 3, 0, 1, 2, 3])
    uv2 = primvars.CreatePrimvar("uv2", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    uv2.Set([(0, 0), (0.5, 0), (1, 0), (0, 1), (0.5, 1), (1, 1)])
    UsdGeom.Camera.Define(stage, "/World/Camera").AddTranslateOp().Set(Gf.Vec3d(1.0, 0.5, 3.0))
    UsdLux.SphereLight.Define(stage, "/World/Light").AddTranslateOp().Set(Gf.Vec3d(0.0, 3.0, 3.0))
    stage.Save()
    return bundle / "scene.usda"


def test_mesh_texture_coordinates_are_read_and_face_varying_ones_unweld_the_mesh(tmp_path: Path) -> None:
    scene = import_usd(_strip_stage(tmp_path))
    mesh = scene.shapes[0]
    assert isinstance(mesh, MeshShape) and mesh.uvs is not None and mesh.uv_sets is not None
    vertices, uvs, uv2 = np.array(mesh.vertices_m), np.array(mesh.uvs), np.array(mesh.uv_sets["uv2"])
    assert len(vertices) == 8 and len(mesh.indices) == 4  # one vertex per face corner, fan-triangulated
    # every corner keeps its own st: the shared edge x = 1 has u = 1 in the left quad, u = 0 in the right
    on_edge = np.isclose(vertices[:, 0], 1.0)
    assert sorted(uvs[on_edge, 0].tolist()) == [0.0, 0.0, 1.0, 1.0]
    np.testing.assert_allclose(uvs[:, 1], vertices[:, 1])  # v = y on both quads
    np.testing.assert_allclose(uv2, vertices[:, :2] * [0.5, 1.0])  # the per-point set follows its points


def test_textures_environment_and_sun_round_trip_through_usd(tmp_path: Path) -> None:
    scene = json.loads((EXAMPLES_DIR / "cornell_box.json").read_text())
    texture = {"type": "image", "path": "t.png", "wrap_u": "mirror", "uv_transform": {"rotation_deg": 30.0}}
    scene["materials"]["textured"] = {"type": "diffuse", "reflectance": texture}
    scene["materials"]["film"] = {
        "type": "thin_film",
        "film_thickness_um": {
            "type": "image",
            "path": "tau.exr",
            "scale": 1.2,
            "offset": 0.1,
            "channel": "g",
        },
        "film_ior": 1.33,
        "substrate": {"ior": 1.0},
    }
    scene["materials"]["tinted"] = {
        "type": "mirror",
        "conductor": "Au",
        "tint": {"type": "image", "path": "t.png"},
    }
    scene["shapes"].append(
        {"type": "mesh", "material": "textured", "vertices_m": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
         "indices": [[0, 1, 2]], "uvs": [[0, 0], [1, 0], [0, 1]],
         "uv_sets": {"uv1": [[0, 0], [2, 0], [0, 2]]}}
    )  # fmt: skip
    scene["emitters"] += [
        {"type": "sun", "direction": [0.2, 1, 0.1], "angular_diameter_deg": 1.0, "irradiance_w_m2": 500.0},
        {"type": "environment", "path": "sky.exr", "radiance_scale": 0.3,
         "transform": {"rotate_axis": [0, 1, 0], "rotate_deg": 40.0}},
    ]  # fmt: skip
    original = validate_scene(scene)
    for name, channels in (("t.png", 3), ("tau.exr", 3), ("sky.exr", 3)):
        write_image(
            tmp_path / name, np.zeros((2, 4, channels), np.uint8 if name.endswith("png") else np.float32)
        )
    scene_to_usd(original, tmp_path / "scene.usda")
    assert import_usd(tmp_path / "scene.usda").to_json_dict() == original.to_json_dict()
    (tmp_path / "tau.exr").unlink()  # the importer checks the images the stage names (hg: strings too)
    with pytest.raises(SceneError) as caught:
        import_usd(tmp_path / "scene.usda")
    assert caught.value.problems[0] == {
        "pointer": "/materials/film/film_thickness_um/path",
        "message": "path 'tau.exr' is not a file in the bundle",
    }
