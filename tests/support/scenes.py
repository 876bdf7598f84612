"""Scenes for tests (JSON documents of schema ``hgrender/scene/v1``): the examples with their film
overridden (``example``; ``tiny_scene`` shrinks one to a few pixels and samples, the way every test that
only needs *a* render does), and the plane under a cylinder light that the viewer tests render."""

from __future__ import annotations

import copy
import json
from typing import Any

from schemas import EXAMPLES_DIR, build


def example(name: str, **film: Any) -> dict[str, Any]:
    """The example scene ``schemas/examples/<name>.json`` (``.json`` optional) with the ``film`` fields
    given replaced."""
    scene = json.loads((EXAMPLES_DIR / f"{name.removesuffix('.json')}.json").read_text())
    scene["film"] = {**scene.get("film", {}), **film}
    return scene


def tiny_scene(
    name: str = "cornell_box", size_px: int = 16, spp: int = 4, max_bands: int = 8
) -> dict[str, Any]:
    """An example shrunk to ``size_px`` square, ``spp`` samples and at most ``max_bands`` bands (a render
    of it takes about a second on 2 cores)."""
    scene = example(name, width=size_px, height=size_px, spp=spp)
    scene["film"]["bands"] = min(scene["film"].get("bands", 16), max_bands)
    return scene


CYLINDER_SIZE_PX = 24
CYLINDER_SPP = 4

# A diffuse plane (y = 0) seen straight from above (camera up = world −z, so image +x = world +x and
# image +y up = world −z) under a thin cylinder light with unit axis a. Seen from a floor point along the
# unit direction d to the cylinder, the source is a strip along the projection of a onto the transverse
# plane, so coherence is longest across it: ℓ₁ ∥ d × a. For a = x̂: d × a = (0, d_z, −d_y), whose
# image-plane (x, −z) components are (0, d_y): vertical (angle ±π/2) at every floor pixel. For
# a = (x̂ + ẑ)/√2: d × a ∝ (d_y, d_z − d_x, −d_y) → image (d_y, d_y): angle π/4 everywhere.
CYLINDER_SCENE: dict[str, Any] = build.scene(
    "plane under a cylinder light",
    camera=build.camera([0, 1.0, 0], [0, 0, 0], up=[0, 0, -1], fov_deg=40),
    film={"width": CYLINDER_SIZE_PX, "height": CYLINDER_SIZE_PX, "bands": 8, "spp": CYLINDER_SPP},
    materials={"floor": {"type": "diffuse", "reflectance": 0.5}},
    shapes=[build.rectangle([0, 0, 0], normal=[0, 1, 0], up=[0, 0, -1], width_m=2, material="floor")],
    emitters=[
        {
            "type": "cylinder",
            "p0_m": [-0.3, 0.5, 0],
            "p1_m": [0.3, 0.5, 0],
            "radius_m": 0.002,
            "spectrum": {"type": "cie_f", "name": "F11"},
            "power_w": 10,
        }
    ],
)


def cylinder_scene(axis_end_m: tuple[float, float] = (0.3, 0.0), **film: Any) -> dict[str, Any]:
    """The scene with film overrides; the cylinder runs from −end to +end in (x, z) at height 0.5 m."""
    scene = copy.deepcopy(CYLINDER_SCENE)
    scene["film"].update(film)
    end_x_m, end_z_m = axis_end_m
    scene["emitters"][0]["p0_m"] = [-end_x_m, 0.5, -end_z_m]
    scene["emitters"][0]["p1_m"] = [end_x_m, 0.5, end_z_m]
    return scene
