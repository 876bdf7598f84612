"""Small scenes (JSON dicts of schema hgrender/scene/v1) for the renderer's reference and paper tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

EXAMPLES_DIR = Path(__file__).resolve().parents[2] / "schemas" / "examples"


def example(name: str, **film: Any) -> dict[str, Any]:
    """An example scene of ``schemas/examples`` with its ``film`` fields overridden."""
    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    scene["film"] = {**scene["film"], **film}
    return scene


def constant_spectrum(power_w: float) -> dict[str, Any]:
    """A flat spectrum of total power ``power_w``: spectral features then come from materials alone."""
    return {"spectrum": {"type": "constant", "value": 1.0}, "power_w": power_w}


def mirror_room(*, size_px: int, spp: int, max_depth: int, bands: int) -> dict[str, Any]:
    """A diffuse floor, a perfect mirror wall behind it and a sphere light: only diffuse + Dirac materials.

    Built so that no surface is ever seen from behind (Mitsuba's BSDFs are one-sided, ``hg_path``'s are
    two-sided): the floor (y = 0, facing up) ends at the mirror (z = −0.5, facing +z), nothing behind either.
    """
    return {
        "schema": "hgrender/scene/v1",
        "name": "mirror room",
        "camera": {
            "type": "perspective",
            "origin_m": [0.0, 0.5, 1.6],
            "target_m": [0.0, 0.25, -0.2],
            "up": [0.0, 1.0, 0.0],
            "fov_deg": 45.0,
        },
        "film": {"width": size_px, "height": size_px, "bands": bands, "spp": spp, "max_depth": max_depth},
        "materials": {
            "floor": {"type": "diffuse", "reflectance": 0.6},
            "mirror": {"type": "mirror", "conductor": "perfect"},
        },
        "shapes": [
            {
                "type": "rectangle",
                "material": "floor",
                "center_m": [0.0, 0.0, 0.1],
                "normal": [0.0, 1.0, 0.0],
                "up": [0.0, 0.0, -1.0],
                "width_m": 1.2,
                "height_m": 1.2,
            },
            {
                "type": "rectangle",
                "material": "mirror",
                "center_m": [0.0, 0.4, -0.5],
                "normal": [0.0, 0.0, 1.0],
                "up": [0.0, 1.0, 0.0],
                "width_m": 1.2,
                "height_m": 0.8,
            },
        ],
        "emitters": [
            {
                "type": "sphere",
                "center_m": [0.25, 0.45, 0.1],
                "radius_m": 0.08,
                "spectrum": {"type": "blackbody", "temperature_k": 4500.0},
                "power_w": 20.0,
            }
        ],
    }
