"""Conventions shared by the USD exporter and importer: the ``hg:`` attribute mirror and frame conversion.

``hg:`` mirror: an hgrender model (a material, a shape, an emitter, the camera) is stored on its prim as
``hg:`` attributes named after its fields in camelCase (``film_thickness_um`` → ``hg:filmThicknessUm``);
nested models become namespaces (``spectrum.temperature_k`` → ``hg:spectrum:temperatureK``). Value types:
float → double, int → int, str → string, 3-vector → double3, list of floats → double[], list of 3-vectors
→ double3[], list of index triples → int3[], 4x4 matrix → matrix4d (stored transposed, i.e. in USD's
row-vector convention). All values are in hgrender's units and world frame (metres, +Y up), whatever the
stage's ``metersPerUnit`` and ``upAxis``.

Frames: a stage point p (stage units, stage up axis) maps to hgrender's world by C = R_up · (metersPerUnit·I),
where R_up is the identity for Y-up and the rotation (x, y, z) → (x, z, −y) for Z-up.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from hgcore.errors import InputError

HG_NAMESPACE = "hg"
#: Key of the root layer's ``customLayerData`` dictionary holding ``schema``, ``name`` and ``film``.
LAYER_DATA_KEY = "hgrender"
#: Attribute holding a material's hgrender id (prim names cannot hold every valid id).
MATERIAL_ID_ATTRIBUTE = "hg:id"
#: Attribute naming the hgrender model type on a prim (``hg:type``).
TYPE_ATTRIBUTE = "hg:type"
#: Linear RGB of the metals for the preview surface only (DCC display): roughly their normal-incidence colour.
CONDUCTOR_PREVIEW_RGB = {
    "Ag": (0.97, 0.96, 0.91),
    "Au": (1.0, 0.78, 0.34),
    "Cu": (0.96, 0.64, 0.54),
    "Al": (0.91, 0.92, 0.92),
    "perfect": (1.0, 1.0, 1.0),
}


def snake_to_camel(name: str) -> str:
    """``film_thickness_um`` → ``filmThicknessUm``."""
    head, *rest = name.split("_")
    return head + "".join(part[:1].upper() + part[1:] for part in rest)


def camel_to_snake(name: str) -> str:
    """``filmThicknessUm`` → ``film_thickness_um``; ``pitchYUm`` → ``pitch_y_um``."""
    return re.sub(r"(?<!^)([A-Z])", r"_\1", name).lower()


def _is_matrix(value: Any) -> bool:
    return (
        isinstance(value, list)
        and len(value) == 4
        and all(isinstance(row, list) and len(row) == 4 for row in value)
    )


def _is_vector_list(value: Any, element_type: type) -> bool:
    return (
        isinstance(value, list)
        and len(value) > 0
        and all(isinstance(row, list) and len(row) == 3 for row in value)
        and all(isinstance(c, element_type) and not isinstance(c, bool) for row in value for c in row)
    )


def write_hg_attributes(prim: Usd.Prim, data: dict[str, Any], namespace: str = HG_NAMESPACE) -> None:
    """Author ``data`` (a model's JSON dict) on ``prim`` as ``hg:`` attributes (None values are skipped)."""
    for field_name, value in data.items():
        name = f"{namespace}:{snake_to_camel(field_name)}"
        if value is None:
            continue
        if isinstance(value, dict):
            write_hg_attributes(prim, value, name)
        elif isinstance(value, bool):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Bool, custom=True).Set(value)
        elif isinstance(value, int):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Int, custom=True).Set(value)
        elif isinstance(value, float):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Double, custom=True).Set(value)
        elif isinstance(value, str):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.String, custom=True).Set(value)
        elif _is_matrix(value):
            matrix = Gf.Matrix4d(*[float(c) for row in np.transpose(value).tolist() for c in row])
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Matrix4d, custom=True).Set(matrix)
        elif _is_vector_list(value, int):
            array = Vt.Vec3iArray([Gf.Vec3i(*row) for row in value])
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Int3Array, custom=True).Set(array)
        elif _is_vector_list(value, float):
            array = Vt.Vec3dArray([Gf.Vec3d(*row) for row in value])
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Double3Array, custom=True).Set(array)
        elif isinstance(value, list) and len(value) == 3 and all(isinstance(c, float) for c in value):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Double3, custom=True).Set(Gf.Vec3d(*value))
        elif isinstance(value, list) and all(isinstance(c, float) for c in value):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.DoubleArray, custom=True).Set(Vt.DoubleArray(value))
        else:
            raise InputError(
                f"{name}: cannot store {type(value).__name__} value {value!r} as a USD attribute"
            )


def usd_value_to_python(value: Any) -> Any:
    """Plain Python (floats, ints, strings, nested lists) from a USD attribute value."""
    if isinstance(value, Gf.Matrix4d | Gf.Matrix4f):
        return np.transpose(np.array(value, dtype=float)).tolist()
    if isinstance(value, Sdf.AssetPath):
        return value.path
    if isinstance(value, bool | int | float | str):
        return value
    if hasattr(value, "__len__") and not isinstance(value, str):
        return [usd_value_to_python(item) for item in value]
    # Gf vectors and quaternion-free scalars: fall back to a float conversion of each component.
    return float(value)


def read_hg_attributes(prim: Usd.Prim, namespace: str = HG_NAMESPACE) -> dict[str, Any]:
    """Every authored ``hg:`` attribute of ``prim`` as a nested dict with snake_case keys."""
    data: dict[str, Any] = {}
    for attribute in prim.GetAuthoredAttributes():
        name = attribute.GetName()
        if not name.startswith(namespace + ":") or name == MATERIAL_ID_ATTRIBUTE:
            continue
        value = attribute.Get()
        if value is None:
            continue
        parts = [camel_to_snake(part) for part in name.split(":")[1:]]
        node = data
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise InputError(f"{name}: conflicts with the attribute {namespace}:{part}")
            node = child
        if isinstance(node.get(parts[-1]), dict):
            raise InputError(f"{name}: conflicts with the namespace {name}:*")
        node[parts[-1]] = usd_value_to_python(value)
    return data


def stage_to_scene_matrix(stage: Usd.Stage) -> np.ndarray:
    """C (4x4, column-vector convention): stage coordinates → hgrender world (metres, +Y up)."""
    meters_per_unit = UsdGeom.GetStageMetersPerUnit(stage)
    if not (np.isfinite(meters_per_unit) and meters_per_unit > 0.0):
        raise InputError(f"metersPerUnit must be finite and > 0, got {meters_per_unit}")
    conversion = np.diag([meters_per_unit, meters_per_unit, meters_per_unit, 1.0])
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        z_up_to_y_up = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
        conversion = z_up_to_y_up @ conversion
    return conversion


def gf_matrix_to_numpy(matrix: Gf.Matrix4d) -> np.ndarray:
    """A Gf matrix (row vectors, translation in the last row) as a column-vector-convention array."""
    return np.transpose(np.array(matrix, dtype=float))


def numpy_to_gf_matrix(matrix: np.ndarray) -> Gf.Matrix4d:
    """Inverse of :func:`gf_matrix_to_numpy`."""
    return Gf.Matrix4d(*[float(c) for c in np.transpose(np.asarray(matrix, dtype=float)).ravel()])


def usd_prim_name(identifier: str, fallback: str) -> str:
    """A valid USD prim name for ``identifier`` (invalid characters → ``_``, leading digit prefixed)."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", identifier) or fallback
    return name if Sdf.Path.IsValidIdentifier(name) else f"_{name}"
