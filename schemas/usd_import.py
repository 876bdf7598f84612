"""Import a USD stage (``.usda``/``.usdc``/``.usd``/``.usdz``, or a zip bundle) into a :class:`Scene`.

Untrusted input goes through :func:`import_usd_isolated`, which runs this module as a child process
(``python -m schemas.usd_import FILE --bundle-dir DIR``) under a wall-clock timeout and address-space /
CPU-time rlimits, so a crash or hang in the USD parser cannot take down the API process; the child's JSON
is validated again in the parent. :func:`import_usd` is the in-process conversion (trusted files, tests).

Mapping (details and units in docs/scenes.md). C maps stage coordinates to hgrender's world: metres
(× ``metersPerUnit``) and +Y up (Z-up stages are rotated by −90° about X).

* A prim with an ``hg:type`` attribute is taken from its ``hg:`` attributes verbatim (hgrender's units and
  world frame; its USD transform is ignored) — this is what :mod:`schemas.usd_export` writes.
* ``UsdGeom.Mesh`` → ``mesh`` (points × world transform, polygons fan-triangulated, winding flipped for
  ``leftHanded``, vertex-interpolated normals kept); ``Cube`` → ``mesh``; ``Sphere``/``Cylinder`` →
  ``sphere``/``cylinder`` (a ``transform`` matrix when the world transform is not a similarity).
  Instances (instanceable prims) are flattened through instance proxies; invisible prims and the
  ``guide``/``proxy`` purposes are skipped; other geometry types are rejected.
* ``UsdGeom.Camera`` (the first one) → look-at camera (a thin lens where fStop > 0: radius
  focalLength/(2·fStop), focused at focusDistance); focalLength and horizontalAperture are in tenths
  of a scene unit, i.e. value × metersPerUnit × 100 mm; clippingRange × metersPerUnit.
* ``UsdLux`` Sphere/Cylinder (length along local X)/Rect (emits along −Z)/Disk lights → emitters with
  ``radiance_scale = intensity · 2^exposure / (K_m ∫ r ȳ dλ)`` (r = 1, or B_λ(colorTemperature) when
  enabled; colour as a tint), divided by the light's area in stage units² when ``normalize`` is on.
  ``DistantLight`` and other light types are rejected (hgrender's coherence needs finite sources).
* ``UsdShade.Material`` → hgrender material from its ``UsdPreviewSurface`` (metallic → mirror/rough
  conductor, opacity < 0.5 → (rough) dielectric with ``ior``, else diffuse ``diffuseColor``), overridden
  field by field by the material's ``hg:`` attributes (``hg:type`` replaces the mapping entirely).
* Film, name: root layer ``customLayerData["hgrender"]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import resource
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade
from pydantic import TypeAdapter, ValidationError

from hgcore.settings import SceneLimits
from schemas.bundle import check_usd_layers, extract_zip_bundle, is_inside
from schemas.errors import SceneError, SceneProblem, without_paths
from schemas.mesh_files import fan_triangulate, load_scene_meshes
from schemas.photometry import rgb_spectrum, tinted_spectrum
from schemas.scene import SCHEMA_ID, Emitter, Material, PerspectiveCamera, Scene, Shape
from schemas.textures import check_scene_images
from schemas.usd_common import (
    CONDUCTOR_PREVIEW_RGB,
    LAYER_DATA_KEY,
    MATERIAL_ID_ATTRIBUTE,
    TYPE_ATTRIBUTE,
    gf_matrix_to_numpy,
    read_hg_attributes,
    snake_to_camel,
    stage_to_scene_matrix,
)
from schemas.validation import problems_from_validation_error, validate_scene

SHAPE_ADAPTER: TypeAdapter[Any] = TypeAdapter(Shape)
EMITTER_ADAPTER: TypeAdapter[Any] = TypeAdapter(Emitter)
MATERIAL_ADAPTER: TypeAdapter[Any] = TypeAdapter(Material)
CAMERA_ADAPTER: TypeAdapter[Any] = TypeAdapter(PerspectiveCamera)
#: UsdPreviewSurface roughness below which surfaces are taken as perfectly smooth (mirror / glass).
SMOOTH_ROUGHNESS = 0.05
#: Correlation length given to rough surfaces mapped from a UsdPreviewSurface roughness, µm.
PREVIEW_CORRELATION_LENGTH_UM = 5.0
DEFAULT_MATERIAL_ID = "default"
EXIT_SCENE_ERROR = 2


def _where(prim: Usd.Prim) -> str:
    return f"<{prim.GetPath()}>"


def _hg_label(pointer: str) -> str:
    """``/spectrum/temperature_k`` → ``hg:spectrum:temperatureK`` (the attribute a user would fix)."""
    parts = [snake_to_camel(part) for part in pointer.split("/")[1:] if not part.isdigit()]
    return ":".join(["hg", *parts]) if parts else "hg:*"


def _validated_element(adapter: TypeAdapter[Any], data: dict[str, Any], prim: Usd.Prim, uses_hg: bool) -> Any:
    """Validate one element's dict, reporting problems at the prim with the offending attribute or field."""
    try:
        return adapter.validate_python(data)
    except ValidationError as error:
        problems = problems_from_validation_error(data, error)
        raise SceneError(
            [
                {
                    "pointer": _where(prim),
                    "message": f"{_hg_label(p['pointer']) if uses_hg else p['pointer'] or '/'}: "
                    f"{p['message']}",
                }
                for p in problems
            ]
        ) from None


def _similarity_scale(matrix: np.ndarray) -> float | None:
    """The uniform scale s if the linear part is s × a rotation (or reflection), else None."""
    linear = matrix[:3, :3]
    gram = linear.T @ linear
    scale_squared = float(np.trace(gram)) / 3.0
    if scale_squared <= 0.0 or not np.allclose(
        gram, scale_squared * np.eye(3), rtol=0.0, atol=1e-6 * scale_squared
    ):
        return None
    return math.sqrt(scale_squared)


def _apply(matrix: np.ndarray, point: Any) -> list[float]:
    return (matrix[:3, :3] @ np.asarray(point, dtype=float) + matrix[:3, 3]).tolist()


def _column_length(matrix: np.ndarray, column: int) -> float:
    return float(np.linalg.norm(matrix[:3, column]))


def _unit(vector: np.ndarray) -> list[float]:
    return (vector / np.linalg.norm(vector)).tolist()


@dataclass
class _StageConverter:
    """Converts one composed stage; collects problems from all prims before failing."""

    stage: Usd.Stage
    limits: SceneLimits
    conversion: np.ndarray
    meters_per_unit: float
    xform_cache: UsdGeom.XformCache = field(
        default_factory=lambda: UsdGeom.XformCache(Usd.TimeCode.Default())
    )
    materials: dict[str, dict[str, Any]] = field(default_factory=dict)
    material_ids: dict[str, str] = field(default_factory=dict)
    problems: list[SceneProblem] = field(default_factory=list)
    triangle_total: int = 0
    vertex_total: int = 0

    def world_matrix(self, prim: Usd.Prim) -> np.ndarray:
        return self.conversion @ gf_matrix_to_numpy(self.xform_cache.GetLocalToWorldTransform(prim))

    # --- materials -------------------------------------------------------------------------------

    def material_id(self, material_prim: Usd.Prim) -> str:
        """The id of a Material prim, converting it on first use (ids are made unique)."""
        path = str(material_prim.GetPath())
        if path in self.material_ids:
            return self.material_ids[path]
        id_attribute = material_prim.GetAttribute(MATERIAL_ID_ATTRIBUTE)
        base_id = (
            str(id_attribute.Get())
            if id_attribute and id_attribute.HasAuthoredValue()
            else material_prim.GetName()
        )
        material_id, suffix = base_id, 2
        while material_id in self.materials:
            material_id, suffix = f"{base_id}_{suffix}", suffix + 1
        self.material_ids[path] = material_id
        model = _validated_element(
            MATERIAL_ADAPTER, self._material_dict(material_prim), material_prim, uses_hg=True
        )
        self.materials[material_id] = model.model_dump(mode="json", exclude_none=True)
        return material_id

    def _material_dict(self, prim: Usd.Prim) -> dict[str, Any]:
        mapped = _preview_surface_material(UsdShade.Material(prim))
        overrides = read_hg_attributes(prim)
        if "type" in overrides and overrides["type"] != mapped["type"]:
            mapped = {}
        return mapped | overrides

    def bound_material_id(self, prim: Usd.Prim) -> str:
        material, _relationship = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if material:
            return self.material_id(material.GetPrim())
        if DEFAULT_MATERIAL_ID not in self.materials:
            self.materials[DEFAULT_MATERIAL_ID] = {"type": "diffuse", "reflectance": 0.5}
        return DEFAULT_MATERIAL_ID

    # --- shapes ----------------------------------------------------------------------------------

    def _count_geometry(self, prim: Usd.Prim, vertex_count: int, triangle_count: int) -> None:
        self.vertex_total += vertex_count
        self.triangle_total += triangle_count
        if self.triangle_total > self.limits.max_triangles:
            raise SceneError.at(
                _where(prim),
                f"the stage exceeds {self.limits.max_triangles} triangles (HGRENDER_MAX_TRIANGLES)",
            )
        if self.vertex_total > self.limits.max_vertices:
            raise SceneError.at(
                _where(prim), f"the stage exceeds {self.limits.max_vertices} vertices (HGRENDER_MAX_VERTICES)"
            )

    def shape(self, prim: Usd.Prim) -> dict[str, Any]:
        if prim.HasAttribute(TYPE_ATTRIBUTE):
            data = read_hg_attributes(prim) | {"material": self.bound_material_id(prim)}
            if data.get("type") == "mesh":
                self._count_geometry(prim, len(data.get("vertices_m", [])), len(data.get("indices", [])))
                # hg: meshes keep their vertices verbatim; their texture coordinates are primvars
                data |= _per_vertex_texture_coordinates(prim, len(data.get("vertices_m", [])))
            model = _validated_element(SHAPE_ADAPTER, data, prim, uses_hg=True)
        else:
            data = self._generic_shape(prim) | {"material": self.bound_material_id(prim)}
            model = _validated_element(SHAPE_ADAPTER, data, prim, uses_hg=False)
        return model.model_dump(mode="json", exclude_none=True)

    def _generic_shape(self, prim: Usd.Prim) -> dict[str, Any]:
        matrix = self.world_matrix(prim)
        scale = _similarity_scale(matrix)
        if prim.IsA(UsdGeom.Sphere):
            radius = float(UsdGeom.Sphere(prim).GetRadiusAttr().Get())
            if scale is not None:
                return {"type": "sphere", "center_m": _apply(matrix, [0, 0, 0]), "radius_m": radius * scale}
            return {
                "type": "sphere",
                "center_m": [0.0, 0.0, 0.0],
                "radius_m": radius,
                "transform": _matrix(matrix),
            }
        if prim.IsA(UsdGeom.Cylinder):
            cylinder = UsdGeom.Cylinder(prim)
            axis = np.eye(3)["XYZ".index(str(cylinder.GetAxisAttr().Get()))]
            half_height = float(cylinder.GetHeightAttr().Get()) / 2.0
            radius = float(cylinder.GetRadiusAttr().Get())
            if scale is not None:
                return {
                    "type": "cylinder",
                    "p0_m": _apply(matrix, -half_height * axis),
                    "p1_m": _apply(matrix, half_height * axis),
                    "radius_m": radius * scale,
                }
            return {
                "type": "cylinder",
                "p0_m": (-half_height * axis).tolist(),
                "p1_m": (half_height * axis).tolist(),
                "radius_m": radius,
                "transform": _matrix(matrix),
            }
        if prim.IsA(UsdGeom.Cube):
            half = float(UsdGeom.Cube(prim).GetSizeAttr().Get()) / 2.0
            corners = np.array(
                [[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)]
            )
            quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
            sizes = np.full(6, 4, dtype=np.int64)
            triangles = fan_triangulate(sizes, np.array(quads, dtype=np.int64).ravel(), _where(prim))
            self._count_geometry(prim, 8, 12)
            vertices = corners @ matrix[:3, :3].T + matrix[:3, 3]
            return {"type": "mesh", "vertices_m": vertices.tolist(), "indices": triangles.tolist()}
        if prim.IsA(UsdGeom.Mesh):
            return self._mesh(prim, matrix)
        raise SceneError.at(
            _where(prim),
            f"unsupported geometry type {prim.GetTypeName()}: convert it to a Mesh, Sphere or Cylinder",
        )

    def _mesh(self, prim: Usd.Prim, matrix: np.ndarray) -> dict[str, Any]:
        mesh = UsdGeom.Mesh(prim)
        face_sizes = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
        points_value = mesh.GetPointsAttr().Get() or []
        self._count_geometry(prim, len(points_value), int(np.maximum(face_sizes - 2, 0).sum()))
        points = np.asarray(points_value, dtype=np.float64).reshape(-1, 3)
        face_indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
        triangles = fan_triangulate(face_sizes, face_indices, _where(prim))
        if triangles.size and (triangles.min() < 0 or triangles.max() >= len(points)):
            raise SceneError.at(_where(prim), "faceVertexIndices refer to points that do not exist")
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            triangles = triangles[:, [0, 2, 1]]
        if np.linalg.det(matrix[:3, :3]) < 0.0:  # a mirroring transform flips the winding too
            triangles = triangles[:, [0, 2, 1]]
        normals_primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("normals")
        if normals_primvar and normals_primvar.HasAuthoredValue():
            normals, interpolation = normals_primvar.ComputeFlattened(), normals_primvar.GetInterpolation()
        else:
            normals, interpolation = mesh.GetNormalsAttr().Get(), mesh.GetNormalsInterpolation()
        world_normals = None
        if normals is not None and interpolation in ("vertex", "varying") and len(normals) == len(points):
            normal_matrix = np.linalg.inv(matrix[:3, :3]).T
            world_normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3) @ normal_matrix.T
            lengths = np.linalg.norm(world_normals, axis=1, keepdims=True)
            world_normals = world_normals / lengths if np.all(lengths > 0.0) else None
        texture_sets = _texture_coordinate_primvars(prim, len(points), len(face_indices))
        if any(values.shape[0] == len(face_indices) != len(points) for values in texture_sets.values()):
            # faceVarying texture coordinates: one vertex per face corner (welded meshes cannot hold them)
            self._count_geometry(prim, len(face_indices) - len(points), 0)
            corners = fan_triangulate(face_sizes, np.arange(len(face_indices)), _where(prim))
            if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
                corners = corners[:, [0, 2, 1]]
            if np.linalg.det(matrix[:3, :3]) < 0.0:
                corners = corners[:, [0, 2, 1]]
            points, triangles = points[face_indices], corners
            world_normals = None if world_normals is None else world_normals[face_indices]
            texture_sets = {
                name: values if values.shape[0] == len(face_indices) else values[face_indices]
                for name, values in texture_sets.items()
            }
        data: dict[str, Any] = {
            "type": "mesh",
            "vertices_m": (points @ matrix[:3, :3].T + matrix[:3, 3]).tolist(),
            "indices": triangles.tolist(),
        }
        if world_normals is not None:
            data["normals"] = world_normals.tolist()
        return data | _texture_coordinate_fields(texture_sets)

    # --- emitters --------------------------------------------------------------------------------

    def emitter(self, prim: Usd.Prim) -> dict[str, Any]:
        if prim.HasAttribute(TYPE_ATTRIBUTE):
            model = _validated_element(EMITTER_ADAPTER, read_hg_attributes(prim), prim, uses_hg=True)
        else:
            model = _validated_element(EMITTER_ADAPTER, self._generic_emitter(prim), prim, uses_hg=False)
        return model.model_dump(mode="json", exclude_none=True)

    def _generic_emitter(self, prim: Usd.Prim) -> dict[str, Any]:
        matrix = self.world_matrix(prim)
        if prim.IsA(UsdLux.SphereLight):
            light: Any = UsdLux.SphereLight(prim)
            if light.GetTreatAsPointAttr().Get():
                raise SceneError.at(
                    _where(prim), "treatAsPoint: point lights have no size; hgrender needs a radius"
                )
            scale = _similarity_scale(matrix)
            if scale is None:
                raise SceneError.at(_where(prim), "SphereLight: non-uniform scale is not supported")
            radius_m = float(light.GetRadiusAttr().Get()) * scale
            geometry = {"type": "sphere", "center_m": _apply(matrix, [0, 0, 0]), "radius_m": radius_m}
            area_m2 = 4.0 * math.pi * radius_m**2
        elif prim.IsA(UsdLux.CylinderLight):
            light = UsdLux.CylinderLight(prim)
            if light.GetTreatAsLineAttr().Get():
                raise SceneError.at(
                    _where(prim), "treatAsLine: line lights have no radius; hgrender needs one"
                )
            half_length = float(light.GetLengthAttr().Get()) / 2.0
            radius_m = float(light.GetRadiusAttr().Get()) * _column_length(matrix, 1)
            p0_m, p1_m = _apply(matrix, [-half_length, 0, 0]), _apply(matrix, [half_length, 0, 0])
            geometry = {"type": "cylinder", "p0_m": p0_m, "p1_m": p1_m, "radius_m": radius_m}
            area_m2 = 2.0 * math.pi * radius_m * math.dist(p0_m, p1_m)
        elif prim.IsA(UsdLux.RectLight):
            light = UsdLux.RectLight(prim)
            width_m = float(light.GetWidthAttr().Get()) * _column_length(matrix, 0)
            height_m = float(light.GetHeightAttr().Get()) * _column_length(matrix, 1)
            geometry = {
                "type": "rectangle",
                "center_m": _apply(matrix, [0, 0, 0]),
                "normal": _unit(-matrix[:3, 2]),
                "up": _unit(matrix[:3, 1]),
                "width_m": width_m,
                "height_m": height_m,
            }
            area_m2 = width_m * height_m
        elif prim.IsA(UsdLux.DiskLight):
            light = UsdLux.DiskLight(prim)
            radius_m = float(light.GetRadiusAttr().Get()) * _column_length(matrix, 0)
            geometry = {
                "type": "disk",
                "center_m": _apply(matrix, [0, 0, 0]),
                "normal": _unit(-matrix[:3, 2]),
                "radius_m": radius_m,
            }
            area_m2 = math.pi * radius_m**2
        elif prim.IsA(UsdLux.DistantLight) or prim.IsA(UsdLux.DomeLight):
            raise SceneError.at(
                _where(prim),
                f'{prim.GetTypeName()} is not mapped yet: give it hg:type "sun" or "environment" with '
                "the fields of hgrender's sun / environment emitter (docs/scenes.md)",
            )
        else:
            raise SceneError.at(_where(prim), f"unsupported light type {prim.GetTypeName()}")
        light_api = UsdLux.LightAPI(prim)
        nits = float(light_api.GetIntensityAttr().Get()) * 2.0 ** float(light_api.GetExposureAttr().Get())
        if not (math.isfinite(nits) and nits > 0.0):
            raise SceneError.at(_where(prim), "inputs:intensity · 2^inputs:exposure must be finite and > 0")
        temperature_k = (
            float(light_api.GetColorTemperatureAttr().Get())
            if light_api.GetEnableColorTemperatureAttr().Get()
            else None
        )
        spectrum, luminance_per_scale = tinted_spectrum(tuple(light_api.GetColorAttr().Get()), temperature_k)
        radiance_scale = nits / luminance_per_scale
        if light_api.GetNormalizeAttr().Get():
            radiance_scale /= area_m2 / self.meters_per_unit**2
        return geometry | {"spectrum": spectrum.model_dump(mode="json"), "radiance_scale": radiance_scale}

    # --- camera ----------------------------------------------------------------------------------

    def camera(self, prim: Usd.Prim) -> dict[str, Any]:
        if prim.HasAttribute(TYPE_ATTRIBUTE):
            data = read_hg_attributes(prim)
            uses_hg = True
        else:
            data, uses_hg = self._generic_camera(prim), False
        model = _validated_element(CAMERA_ADAPTER, data, prim, uses_hg)
        return model.model_dump(mode="json", exclude_none=True)

    def _generic_camera(self, prim: Usd.Prim) -> dict[str, Any]:
        camera = UsdGeom.Camera(prim)
        if camera.GetProjectionAttr().Get() != UsdGeom.Tokens.perspective:
            raise SceneError.at(_where(prim), "projection: only perspective cameras are supported")
        matrix = self.world_matrix(prim)
        origin = np.asarray(_apply(matrix, [0, 0, 0]))
        forward = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0])
        up = matrix[:3, :3] @ np.array([0.0, 1.0, 0.0])
        # Lens attributes are in tenths of a scene unit: value × metersPerUnit / 10 m = value × mpu × 100 mm.
        millimetres_per_value = self.meters_per_unit * 100.0
        near, far = camera.GetClippingRangeAttr().Get()
        focal_length_mm = float(camera.GetFocalLengthAttr().Get()) * millimetres_per_value
        data = {
            "type": "perspective",
            "origin_m": origin.tolist(),
            "target_m": (origin + np.asarray(_unit(forward))).tolist(),
            "up": _unit(up),
            "focal_length_mm": focal_length_mm,
            "sensor_width_mm": float(camera.GetHorizontalApertureAttr().Get()) * millimetres_per_value,
            "near_clip_m": float(near) * self.meters_per_unit,
            "far_clip_m": float(far) * self.meters_per_unit,
        }
        # Depth of field: fStop > 0 is a thin lens of radius f/(2N) focused at focusDistance (scene units,
        # along the view axis); fStop 0, USD's default, a pinhole.
        f_stop = float(camera.GetFStopAttr().Get() or 0.0)
        if f_stop > 0.0:
            focus_m = float(camera.GetFocusDistanceAttr().Get() or 0.0) * self.meters_per_unit
            if not focus_m > 0.0:
                raise SceneError.at(_where(prim), "focusDistance: must be > 0 when fStop > 0 (a thin lens)")
            data["aperture_radius_m"] = focal_length_mm * 1e-3 / (2.0 * f_stop)
            data["focus_distance_m"] = focus_m
        return data


def _texture_coordinate_primvars(
    prim: Usd.Prim, point_count: int, corner_count: int
) -> dict[str, np.ndarray]:
    """The mesh's ``texCoord2f``/``float2`` primvars with one value per point (``vertex``/``varying``) or
    per face corner (``faceVarying``), flattened (indexed primvars resolved), by name; other
    interpolations (constant, uniform) carry no per-point coordinates and are skipped."""
    sets: dict[str, np.ndarray] = {}
    for primvar in UsdGeom.PrimvarsAPI(prim).GetPrimvars():
        type_name = primvar.GetTypeName()
        if type_name not in (Sdf.ValueTypeNames.TexCoord2fArray, Sdf.ValueTypeNames.Float2Array):
            continue
        if not primvar.HasAuthoredValue():
            continue
        values = primvar.ComputeFlattened()
        if values is None:
            continue
        array = np.asarray(values, dtype=np.float64).reshape(-1, 2)
        interpolation = primvar.GetInterpolation()
        expected = point_count if interpolation in ("vertex", "varying") else corner_count
        if interpolation in ("vertex", "varying", "faceVarying") and array.shape[0] == expected:
            sets[primvar.GetPrimvarName()] = array
    return sets


def _texture_coordinate_fields(sets: dict[str, np.ndarray]) -> dict[str, Any]:
    """``uvs`` (the set ``st``) and ``uv_sets`` (the others) of a mesh model."""
    fields: dict[str, Any] = {}
    if "st" in sets:
        fields["uvs"] = sets["st"].tolist()
    others = {name: values.tolist() for name, values in sets.items() if name != "st"}
    if others:
        fields["uv_sets"] = others
    return fields


def _per_vertex_texture_coordinates(prim: Usd.Prim, vertex_count: int) -> dict[str, Any]:
    """The per-vertex texture coordinate primvars of an ``hg:`` mesh (exported by ``usd_export``)."""
    sets = _texture_coordinate_primvars(prim, vertex_count, -1)
    return _texture_coordinate_fields(sets)


def _matrix(matrix: np.ndarray) -> dict[str, Any]:
    return {"matrix": matrix.tolist()}


def _preview_surface_material(material: UsdShade.Material) -> dict[str, Any]:
    """The nearest hgrender material to a UsdPreviewSurface (textures are not evaluated: input values).

    GGX α = roughness² is taken as the RMS slope m of a Gaussian surface with correlation length ℓ,
    m = √2 σ/ℓ, so σ = α ℓ/√2 with ℓ = ``PREVIEW_CORRELATION_LENGTH_UM``.
    """
    shader = material.ComputeSurfaceSource()[0] if material else None
    if not shader or shader.GetIdAttr().Get() != "UsdPreviewSurface":
        return {"type": "diffuse", "reflectance": 0.5}

    def value(name: str, default: Any) -> Any:
        shader_input = shader.GetInput(name)
        authored = shader_input.Get() if shader_input else None
        return default if authored is None else authored

    rgb = tuple(min(1.0, max(0.0, float(c))) for c in value("diffuseColor", (0.18, 0.18, 0.18)))
    roughness = min(1.0, max(0.0, float(value("roughness", 0.5))))
    roughness_rms_um = roughness**2 * PREVIEW_CORRELATION_LENGTH_UM / math.sqrt(2.0)
    if float(value("metallic", 0.0)) >= 0.5:
        conductor = min(
            ("Ag", "Au", "Cu", "Al"),
            key=lambda name: sum((a - b) ** 2 for a, b in zip(CONDUCTOR_PREVIEW_RGB[name], rgb, strict=True)),
        )
        if roughness < SMOOTH_ROUGHNESS:
            return {"type": "mirror", "conductor": conductor}
        return {
            "type": "rough_conductor",
            "conductor": conductor,
            "roughness_rms_um": roughness_rms_um,
            "correlation_length_um": PREVIEW_CORRELATION_LENGTH_UM,
        }
    if float(value("opacity", 1.0)) < 0.5:
        ior = max(1.0, float(value("ior", 1.5)))
        if roughness < SMOOTH_ROUGHNESS:
            return {"type": "dielectric", "ior": ior}
        return {
            "type": "rough_dielectric",
            "ior": ior,
            "roughness_rms_um": roughness_rms_um,
            "correlation_length_um": PREVIEW_CORRELATION_LENGTH_UM,
        }
    reflectance = rgb_spectrum(rgb)
    if reflectance.type == "constant":
        return {"type": "diffuse", "reflectance": reflectance.value}
    return {"type": "diffuse", "reflectance": reflectance.model_dump(mode="json")}


def convert_stage(stage: Usd.Stage, limits: SceneLimits, default_name: str) -> dict[str, Any]:
    """The scene dict (not yet validated as a whole) of a composed ``stage``."""
    converter = _StageConverter(
        stage=stage,
        limits=limits,
        conversion=stage_to_scene_matrix(stage),
        meters_per_unit=UsdGeom.GetStageMetersPerUnit(stage),
    )
    layer_data = dict(stage.GetRootLayer().customLayerData.get(LAYER_DATA_KEY, {}))
    if layer_data.get("schema", SCHEMA_ID) != SCHEMA_ID:
        converter.problems.append(
            {"pointer": "customLayerData:hgrender:schema", "message": f"must be {SCHEMA_ID!r}"}
        )
    camera: dict[str, Any] | None = None
    shapes: list[dict[str, Any]] = []
    emitters: list[dict[str, Any]] = []
    prims = iter(Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    prim_count = 0
    for prim in prims:
        prim_count += 1
        if prim_count > limits.max_usd_prims:
            raise SceneError.at(
                _where(prim), f"the stage has more than {limits.max_usd_prims} prims (HGRENDER_MAX_USD_PRIMS)"
            )
        if prim.IsPseudoRoot():
            continue
        try:
            if prim.IsA(UsdGeom.Imageable):
                imageable = UsdGeom.Imageable(prim)
                if (
                    imageable.ComputeVisibility() == UsdGeom.Tokens.invisible
                    or imageable.ComputePurpose()
                    in (
                        UsdGeom.Tokens.guide,
                        UsdGeom.Tokens.proxy,
                    )
                ):
                    prims.PruneChildren()
                    continue
            if prim.IsA(UsdShade.Material):
                converter.material_id(prim)
                prims.PruneChildren()
            elif prim.IsA(UsdGeom.PointInstancer):
                raise SceneError.at(
                    _where(prim), "PointInstancer is not supported: use instanceable references instead"
                )
            elif prim.IsA(UsdGeom.Camera):
                if camera is None:
                    camera = converter.camera(prim)
            elif prim.HasAPI(UsdLux.LightAPI):
                emitters.append(converter.emitter(prim))
            elif prim.HasAttribute(TYPE_ATTRIBUTE) or prim.IsA(UsdGeom.Gprim):
                shapes.append(converter.shape(prim))
        except SceneError as error:
            converter.problems.extend(error.problems)
        except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError, Tf.ErrorException) as error:
            message = f"cannot convert: {without_paths(str(error))}"
            converter.problems.append({"pointer": _where(prim), "message": message})
    if camera is None:
        converter.problems.append({"pointer": "<stage>", "message": "the stage has no UsdGeom.Camera"})
    if not emitters:
        converter.problems.append(
            {"pointer": "<stage>", "message": "the stage has no supported UsdLux light"}
        )
    if converter.problems:
        raise SceneError(converter.problems)
    return {
        "schema": SCHEMA_ID,
        "name": str(layer_data.get("name", default_name))[:200],
        "camera": camera,
        "film": dict(layer_data.get("film", {})),
        "materials": converter.materials,
        "shapes": shapes,
        "emitters": emitters,
    }


def import_usd(path: str | os.PathLike[str], bundle_dir: str | os.PathLike[str] | None = None,
               limits: SceneLimits | None = None) -> Scene:  # fmt: skip
    """Convert the USD file at ``path`` (inside ``bundle_dir``, default its directory) in this process.

    Checks every asset path and the limits before composing the stage. For untrusted files use
    :func:`import_usd_isolated`.
    """
    limits = limits if limits is not None else SceneLimits()
    root_file = Path(path).resolve()
    bundle = Path(bundle_dir).resolve() if bundle_dir is not None else root_file.parent
    layers = check_usd_layers(root_file, bundle, limits)  # keeps the checked layers open for the stage
    try:
        stage = Usd.Stage.Open(layers[0], Usd.Stage.LoadAll)
    except Tf.ErrorException as error:
        message = f"cannot compose the stage: {without_paths(str(error))}"
        raise SceneError.at(f"bundle:{root_file.name}", message) from None
    scene = validate_scene(convert_stage(stage, limits, root_file.stem), limits)
    load_scene_meshes(scene, bundle, limits)  # mesh files must exist, parse and fit the triangle budget
    check_scene_images(scene, bundle, limits)  # images must exist, be readable and fit the texture limits
    return scene


def _import_for_child(path: Path, bundle_dir: Path, limits: SceneLimits) -> Scene:
    if path.suffix.lower() == ".zip":
        root_file = extract_zip_bundle(path, bundle_dir, limits)
        return import_usd(root_file, bundle_dir, limits)
    if not is_inside(path, bundle_dir):
        raise SceneError.at(f"bundle:{path.name}", "the scene file must be inside the bundle directory")
    return import_usd(path, bundle_dir, limits)


def import_usd_isolated(
    path: str | os.PathLike[str],
    bundle_dir: str | os.PathLike[str] | None = None,
    limits: SceneLimits | None = None,
    timeout_s: float | None = None,
) -> Scene:
    """Import untrusted USD in a child process with a timeout and rlimits; return the validated Scene.

    ``path``: a USD file inside ``bundle_dir`` (default: its directory), or a ``.zip`` bundle, extracted
    into ``bundle_dir`` (must be empty or missing; default: a temporary directory removed afterwards).
    A timeout, crash or memory exhaustion of the child becomes a :class:`SceneError`.
    """
    limits = limits if limits is not None else SceneLimits()
    timeout_s = timeout_s if timeout_s is not None else limits.usd_timeout_s
    source = Path(path).resolve()
    where = f"bundle:{source.name}"
    if not source.is_file():
        raise SceneError.at(where, "file not found")
    with contextlib.ExitStack() as cleanup:
        if bundle_dir is not None:
            bundle = Path(bundle_dir).resolve()
        elif source.suffix.lower() == ".zip":
            bundle = Path(cleanup.enter_context(tempfile.TemporaryDirectory(prefix="hgrender-bundle-")))
        else:
            bundle = source.parent
        command = [
            sys.executable, "-m", "schemas.usd_import", str(source), "--bundle-dir", str(bundle),
            "--limits-json", limits.model_dump_json(), "--cpu-seconds", str(math.ceil(timeout_s) + 1),
        ]  # fmt: skip
        # No USD plugin or search-path settings from the server's environment reach the parser.
        environment = {k: v for k, v in os.environ.items() if not k.startswith(("PXR_", "TF_", "USD_"))}
        environment["OPENBLAS_NUM_THREADS"] = "1"
        try:
            completed = subprocess.run(
                command, capture_output=True, timeout=timeout_s, env=environment, stdin=subprocess.DEVNULL
            )
        except subprocess.TimeoutExpired:
            raise SceneError.at(where, f"USD import timed out after {timeout_s:g} s") from None
    payload: dict[str, Any] = {}
    with contextlib.suppress(ValueError, IndexError):
        payload = json.loads(completed.stdout.decode("utf-8").strip().splitlines()[-1])
    if completed.returncode == 0 and "scene" in payload:
        return validate_scene(payload["scene"], limits)
    if completed.returncode == EXIT_SCENE_ERROR and payload.get("problems"):
        raise SceneError(payload["problems"])
    stderr = without_paths(completed.stderr.decode("utf-8", errors="replace"))
    stderr_tail = stderr.strip().splitlines()[-1:] or [""]
    if completed.returncode < 0:
        signal_name = signal.Signals(-completed.returncode).name
        raise SceneError.at(where, f"the USD parser crashed ({signal_name}) {stderr_tail[0][:200]}".strip())
    raise SceneError.at(
        where, f"the USD parser failed (exit {completed.returncode}): {stderr_tail[0][:300] or 'no message'}"
    )


def _apply_own_rlimits(limits: SceneLimits, cpu_seconds: int) -> None:
    """Limit this (child) process: address space, CPU time, and the size of any file it writes."""
    resource.setrlimit(resource.RLIMIT_AS, (limits.max_usd_memory_bytes, limits.max_usd_memory_bytes))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_seconds, cpu_seconds + 1))
    resource.setrlimit(resource.RLIMIT_FSIZE, (limits.max_file_bytes, limits.max_file_bytes))


def main(argv: list[str] | None = None) -> int:
    """Child entry point: print ``{"scene": ...}`` (exit 0) or ``{"problems": [...]}`` (exit 2), one line."""
    parser = argparse.ArgumentParser(prog="python -m schemas.usd_import", description=__doc__.splitlines()[0])
    parser.add_argument("path", type=Path)
    parser.add_argument("--bundle-dir", type=Path, default=None)
    parser.add_argument("--limits-json", default=None, help="SceneLimits as JSON (default: from environment)")
    parser.add_argument("--cpu-seconds", type=int, default=None, help="apply rlimits to this process")
    arguments = parser.parse_args(argv)
    limits = (
        SceneLimits.model_validate_json(arguments.limits_json) if arguments.limits_json else SceneLimits()
    )
    if arguments.cpu_seconds is not None:
        _apply_own_rlimits(limits, arguments.cpu_seconds)
    path = arguments.path.resolve()
    bundle_dir = (arguments.bundle_dir or path.parent).resolve()
    try:
        scene = _import_for_child(path, bundle_dir, limits)
    except SceneError as error:
        print(json.dumps({"problems": error.problems}))
        return EXIT_SCENE_ERROR
    except (MemoryError, RecursionError) as error:
        print(
            json.dumps(
                {"problems": [{"pointer": f"bundle:{path.name}", "message": f"out of resources: {error!r}"}]}
            )
        )
        return EXIT_SCENE_ERROR
    print(json.dumps({"scene": scene.to_json_dict()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
