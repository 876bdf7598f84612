"""A USD stage authored with usd-core renders, and its diagnostics show the CylinderLight's anisotropy.

Z-up stage in metres: a 4 m × 4 m floor mesh bound to a thin-film material described by ``hg:`` attributes,
a camera 3 m above it looking down, and a ``UsdLux.CylinderLight`` (20 cm long along its local X, radius
1 mm) 1 m above the floor. The floor under the light sees the tube side-on, so the coherence anisotropy at
the image centre is that of a uniform L × 2R strip, ℓ₁/ℓ₂ = L/(2R) (the calculator's closed form); the 2 %
tolerance is the BRIEF's, far above the < 0.1 % in-pixel variation of the geometry.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

from hgcore.artifacts.exr import read_exr
from hgcore.optics.calculator import coherence_at
from schemas.usd_import import import_usd_isolated
from worker.render.chunks import render_scene

LENGTH_M = 0.2
RADIUS_M = 0.001


def author_stage(directory: Path) -> Path:
    stage = Usd.Stage.CreateNew(str(directory / "scene.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetMetadata(
        "customLayerData", {"hgrender": {"name": "usd cylinder", "film": {"width": 24, "height": 24}}}
    )
    UsdGeom.Xform.Define(stage, "/World")
    coating = UsdShade.Material.Define(stage, "/World/Looks/Coating")
    for name, type_name, value in [
        ("hg:type", Sdf.ValueTypeNames.Token, "thin_film"),
        ("hg:filmThicknessUm", Sdf.ValueTypeNames.Double, 0.5),
        ("hg:filmIor", Sdf.ValueTypeNames.Double, 1.45),
        ("hg:substrate:conductor", Sdf.ValueTypeNames.Token, "Al"),
        ("hg:roughnessRmsUm", Sdf.ValueTypeNames.Double, 0.3),
        ("hg:correlationLengthUm", Sdf.ValueTypeNames.Double, 1.0),
    ]:
        coating.GetPrim().CreateAttribute(name, type_name, custom=True).Set(value)
    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")
    floor.CreatePointsAttr([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)])
    floor.CreateFaceVertexCountsAttr([4])
    floor.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    UsdShade.MaterialBindingAPI.Apply(floor.GetPrim()).Bind(coating)
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 3.0))  # USD cameras look along their −Z: straight down
    camera.CreateFocalLengthAttr(0.5)  # lens values are in tenths of a stage unit: 50 mm
    camera.CreateHorizontalApertureAttr(0.36)
    camera.CreateClippingRangeAttr(Gf.Vec2f(0.01, 100.0))
    light = UsdLux.CylinderLight.Define(stage, "/World/Tube")
    light.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 1.0))
    light.CreateLengthAttr(LENGTH_M)
    light.CreateRadiusAttr(RADIUS_M)
    light.CreateIntensityAttr(5000.0)
    stage.Save()
    return directory / "scene.usda"


def test_usd_stage_renders_with_the_cylinder_anisotropy(tmp_path: Path) -> None:
    scene = import_usd_isolated(author_stage(tmp_path), timeout_s=60)
    assert scene.emitters[0].type == "cylinder"
    render_scene(scene, tmp_path / "out", spp=4)
    channels = read_exr(tmp_path / "out" / "image.exr").channels
    weight = channels["coherence.weight"]
    anisotropy = channels["coherence.anisotropy"]
    depth = channels["depth"]
    centre = anisotropy[10:14, 10:14][(weight[10:14, 10:14] > 0) & (np.abs(depth[10:14, 10:14] - 3.0) < 0.05)]
    assert centre.size >= 8
    expected = coherence_at("cylinder", radius_m=RADIUS_M, length_m=LENGTH_M, distance_m=1.0)["anisotropy"]
    assert expected == pytest.approx(LENGTH_M / (2 * RADIUS_M), rel=1e-9)  # side-on strip: L/(2R)
    assert np.all(np.abs(centre / expected - 1.0) < 0.02), (centre, expected)
