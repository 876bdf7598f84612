"""Builders for scene documents (JSON dicts of schema ``hgrender/scene/v1``) from Python.

Each returns the plain dict the schema validates (``schemas.validate_scene``), so a scene written with
them is the same document as one written by hand in JSON: positions in metres, directions as unit-free
vectors, angles in degrees. They check nothing themselves — validation is the schema's — and exist so that
scripts, tests and the API's OpenAPI example state a camera, a rectangle or a film in one line instead of
seven.

>>> scene("lit floor", camera=camera([0, 1, 3], [0, 0, 0], fov_deg=40),
...       film=film(32, bands=8, spp=16), materials={"white": {"type": "diffuse", "reflectance": 0.75}},
...       shapes=[rectangle([0, 0, 0], normal=[0, 1, 0], up=[0, 0, -1], width_m=2, material="white")],
...       emitters=[sphere([0, 1.5, 0], 0.1, spectrum={"type": "d65"}, power_w=40.0)])["name"]
'lit floor'
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

Vector = Sequence[float]
Document = dict[str, Any]


def camera(
    origin_m: Vector, target_m: Vector, *, fov_deg: float | None = None, up: Vector | None = None
) -> Document:
    """A perspective camera at ``origin_m`` looking at ``target_m``; ``up`` and ``fov_deg`` default as in
    the schema when omitted."""
    document: Document = {"type": "perspective", "origin_m": list(origin_m), "target_m": list(target_m)}
    if up is not None:
        document["up"] = list(up)
    if fov_deg is not None:
        document["fov_deg"] = fov_deg
    return document


def film(width: int, height: int | None = None, *, bands: int, spp: int, **fields: Any) -> Document:
    """A film of ``width`` × ``height`` pixels (square when ``height`` is omitted); ``fields`` adds any
    other film field (``max_depth``, ``wavelength_min_nm``, ...)."""
    return {
        "width": width,
        "height": width if height is None else height,
        "bands": bands,
        "spp": spp,
        **fields,
    }


def rectangle(
    center_m: Vector,
    *,
    normal: Vector,
    up: Vector,
    width_m: float,
    height_m: float | None = None,
    **fields: Any,
) -> Document:
    """A rectangle (a shape with ``material=…``, or an emitter with ``spectrum=…`` and ``power_w=…`` or
    ``radiance_scale=…``) centred at ``center_m``, facing ``normal``, its height along ``up``; square when
    ``height_m`` is omitted."""
    return {
        "type": "rectangle",
        **({"material": fields.pop("material")} if "material" in fields else {}),
        "center_m": list(center_m),
        "normal": list(normal),
        "up": list(up),
        "width_m": width_m,
        "height_m": width_m if height_m is None else height_m,
        **fields,
    }


def sphere(center_m: Vector, radius_m: float, **fields: Any) -> Document:
    """A sphere (a shape with ``material=…``, or an emitter with ``spectrum=…`` and its power)."""
    return {
        "type": "sphere",
        **({"material": fields.pop("material")} if "material" in fields else {}),
        "center_m": list(center_m),
        "radius_m": radius_m,
        **fields,
    }


def scene(
    name: str,
    *,
    camera: Document,
    film: Document | None = None,
    materials: dict[str, Document],
    shapes: list[Document],
    emitters: list[Document],
) -> Document:
    """A whole scene document; ``film`` defaults as in the schema when omitted."""
    document: Document = {"schema": "hgrender/scene/v1", "name": name, "camera": camera}
    if film is not None:
        document["film"] = film
    return {**document, "materials": materials, "shapes": shapes, "emitters": emitters}
