"""White furnace: an object inside a closed box whose walls all emit the same uniform radiance.

Every ray leaving the object ends on a wall, so a lossless object (no absorption anywhere, any number of
bounces) must look exactly as bright as the walls. The walls are six inward-facing rectangle emitters of
an equal-energy spectrum; the camera sits inside the box. ``furnace_ratio`` returns the mean of the object's
pixels over the walls' radiance and its standard error from the per-pixel variance of the mean that the
pixel-to-pixel scatter, averaged over the bands.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.artifacts.exr import read_exr
from schemas import validate_scene
from worker.render.chunks import render_scene

BOX_HALF_SIZE_M = 3.0
WALLS = [  # (centre axis, sign): the wall at sign·half-size along that axis, emitting inwards
    (axis, sign) for axis in range(3) for sign in (-1.0, 1.0)
]
WALL_RADIANCE = 1.0  # per band: a constant spectrum of 1 at radiance_scale 1 (the walls' pixels read it)


def _wall(axis: int, sign: float) -> dict[str, Any]:
    centre = [0.0, 0.0, 0.0]
    centre[axis] = sign * BOX_HALF_SIZE_M
    normal = [0.0, 0.0, 0.0]
    normal[axis] = -sign
    up = [0.0, 0.0, 0.0]
    up[(axis + 1) % 3] = 1.0
    side = 2.0 * BOX_HALF_SIZE_M + 0.02  # overlap at the edges: no gaps between walls
    return {
        "type": "rectangle",
        "center_m": centre,
        "normal": normal,
        "up": up,
        "width_m": side,
        "height_m": side,
        "spectrum": {"type": "constant", "value": 1.0},
        "radiance_scale": WALL_RADIANCE,
    }


def furnace_scene(
    material: dict[str, Any], shape: dict[str, Any], *, size_px: int = 24, spp: int = 64, max_depth: int = 48
) -> dict[str, Any]:
    """``shape`` (a shapes entry without ``material``) made of ``material`` inside the glowing box."""
    return {
        "schema": "hgrender/scene/v1",
        "name": "white furnace",
        "camera": {
            "type": "perspective",
            "origin_m": [0.0, 0.3, -2.5],
            "target_m": [0.0, 0.0, 0.0],
            "up": [0.0, 1.0, 0.0],
            "fov_deg": 30.0,
        },
        "film": {"width": size_px, "height": size_px, "bands": 4, "spp": spp, "max_depth": max_depth},
        "materials": {"probe": material},
        "shapes": [{**shape, "material": "probe"}],
        "emitters": [_wall(axis, sign) for axis, sign in WALLS],
    }


def sphere(radius_m: float = 0.6) -> dict[str, Any]:
    return {"type": "sphere", "center_m": [0.0, 0.0, 0.0], "radius_m": radius_m}


def _read(path: Path) -> dict[str, np.ndarray]:
    return {name: values.astype(float) for name, values in read_exr(path).channels.items()}


def _object_bands(scene: dict[str, Any], out_dir: Path, seed: int) -> list[np.ndarray]:
    """Render; per band, the object pixels' radiance over the walls'. Object pixels are those whose first
    hit is nearer than any wall can be (depth < 2.5 m)."""
    render_scene(validate_scene(scene), out_dir, seed=seed)
    image = _read(out_dir / "image.exr")
    bands = sorted(name for name in image if name.startswith("S0."))
    mask = image["depth"] < 2.5
    assert mask.sum() >= 20, "the object covers too few pixels"
    return [image[name][mask] / WALL_RADIANCE for name in bands]


def _mean_and_error(values: np.ndarray) -> tuple[float, float]:
    """Mean and its standard error from the pixel-to-pixel scatter over √N (conservative: it includes any
    real variation with angle)."""
    return float(values.mean()), float(np.std(values, ddof=1) / math.sqrt(values.size))


def furnace_ratio(scene: dict[str, Any], out_dir: Path, seed: int = 1) -> tuple[float, float]:
    """(mean object radiance / wall radiance, its standard error), the bands averaged per pixel."""
    return _mean_and_error(np.mean(_object_bands(scene, out_dir, seed), axis=0))


def furnace_band_ratios(scene: dict[str, Any], out_dir: Path, seed: int = 1) -> list[tuple[float, float]]:
    """``furnace_ratio`` per band: biases that differ between the bands (the spectrum's ends) show here."""
    return [_mean_and_error(values) for values in _object_bands(scene, out_dir, seed)]


def box(half_extents_m: tuple[float, float, float]) -> dict[str, Any]:
    """A closed box mesh centred at the origin, triangles wound counter-clockwise seen from outside
    (Mitsuba's face normal cross(v1 − v0, v2 − v0) points out, so 'inside' is inside)."""
    vertices: list[list[float]] = []
    indices: list[list[int]] = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(normal, u)
            corners = [normal + a * u + b * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            base = len(vertices)
            vertices += [(corner * np.asarray(half_extents_m)).tolist() for corner in corners]
            indices += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return {"type": "mesh", "vertices_m": vertices, "indices": indices}
