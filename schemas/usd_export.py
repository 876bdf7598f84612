"""Export a :class:`schemas.scene.Scene` to USD (``.usda``, ``.usdc``, ``.usd`` or ``.usdz``).

The stage is Y-up with ``metersPerUnit = 1``. Every element is written twice over: as standard UsdGeom /
UsdLux / UsdShade data so DCC tools display it, and as its exact hgrender model in ``hg:`` attributes
(see :mod:`schemas.usd_common`) so that :func:`schemas.usd_import.import_usd` gives back an equal scene.

Standard data written (units: stage units = metres):
* camera → ``UsdGeom.Camera``; horizontalAperture/focalLength in tenths of a scene unit (USD's lens units),
  so a 36 mm aperture is 0.36 at 1 m per unit; clippingRange = (near_clip_m, far_clip_m); a thin lens as
  fStop = focal length / (2 · aperture radius) and focusDistance (scene units).
* sphere / cylinder shapes → ``UsdGeom.Sphere`` / ``UsdGeom.Cylinder`` (axis Z) placed by xform ops;
  rectangle, disk (48-gon), inline meshes and procedural shapes (shell, wavy sheet, optical disc, backdrop:
  the generated triangles, vertex normals and ``st`` texture coordinates) → ``UsdGeom.Mesh``; mesh files →
  an ``Xform`` with ``hg:path``.
* emitters → ``UsdLux`` Sphere/Cylinder/Rect/Disk lights, ``inputs:intensity`` = the emitter's luminance in
  nits (K_m·c·∫ s ȳ dλ, :mod:`schemas.photometry`), colour white, exposure 0, normalize off; an
  environment → ``DomeLight`` (its image as ``inputs:texture:file``, format ``latlong``: the same OpenEXR
  convention), a sun → ``DistantLight`` (``inputs:angle`` = its angular diameter, local −Z from the sun).
* materials → ``UsdShade.Material`` with a ``UsdPreviewSurface`` approximating the look, plus ``hg:id``; a
  textured diffuse reflectance → a ``UsdUVTexture`` (file, wrapS/T, sourceColorSpace, scale/bias) read
  through a ``UsdPrimvarReader_float2`` of its uv set into ``diffuseColor``.
* mesh texture coordinates (``uvs``, ``uv_sets``) → ``texCoord2f[]`` primvars (``st`` and the set names),
  vertex interpolation.
* film, name and schema id → root layer ``customLayerData["hgrender"]``.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, UsdUtils, Vt

from hgcore.errors import InputError
from schemas.photometry import emitter_radiance_scale, luminance_per_radiance_scale, reflectance_rgb
from schemas.procedural import generate_mesh
from schemas.scene import (
    PROCEDURAL_SHAPE_TYPES,
    ConstantSpectrum,
    CylinderEmitter,
    CylinderShape,
    DielectricMaterial,
    DiffuseMaterial,
    DiskEmitter,
    DiskShape,
    EnvironmentEmitter,
    GratingMaterial,
    ImageTexture,
    MeshFileShape,
    MeshShape,
    MirrorMaterial,
    PerspectiveCamera,
    RectangleEmitter,
    RectangleShape,
    RoughConductorMaterial,
    RoughDielectricMaterial,
    Scene,
    SphereEmitter,
    SphereShape,
    SunEmitter,
    ThinFilmMaterial,
)
from schemas.usd_common import (
    CONDUCTOR_PREVIEW_RGB,
    LAYER_DATA_KEY,
    MATERIAL_ID_ATTRIBUTE,
    numpy_to_gf_matrix,
    usd_prim_name,
    write_hg_attributes,
)

USD_SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")
#: Sensor width written for cameras given by field of view, mm (full-frame 35 mm film).
DEFAULT_SENSOR_WIDTH_MM = 36.0
DISK_POLYGON_SIDES = 48


def _unit(vector: Any) -> np.ndarray:
    array = np.asarray(vector, dtype=float)
    return array / np.linalg.norm(array)


def _frame_matrix(x_axis: np.ndarray, y_axis: np.ndarray, z_axis: np.ndarray, origin: Any) -> np.ndarray:
    """4x4 column-vector matrix whose columns are the given axes and origin."""
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = x_axis, y_axis, z_axis, origin
    return matrix


def _any_perpendicular(direction: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    return _unit(np.cross(direction, helper))


def _axis_frame(p0_m: list[float], p1_m: list[float], axis_column: int) -> np.ndarray:
    """A rigid frame centred between p0 and p1 whose ``axis_column`` axis points from p0 to p1."""
    axis = _unit(np.subtract(p1_m, p0_m))
    first = _any_perpendicular(axis)
    second = np.cross(axis, first)
    centre = (np.asarray(p0_m) + np.asarray(p1_m)) / 2.0
    if axis_column == 0:  # X along the axis (UsdLux CylinderLight)
        return _frame_matrix(axis, first, second, centre)
    return _frame_matrix(first, second, axis, centre)  # Z along the axis (UsdGeom.Cylinder, axis "Z")


def _rectangle_frame(center_m: list[float], normal: list[float], up: list[float]) -> np.ndarray:
    """Frame of a rectangle: +Y along ``up`` (projected into the plane), −Z along ``normal`` (UsdLux)."""
    unit_normal = _unit(normal)
    y_axis = _unit(np.asarray(up, dtype=float) - np.dot(up, unit_normal) * unit_normal)
    x_axis = np.cross(y_axis, -unit_normal)
    return _frame_matrix(x_axis, y_axis, -unit_normal, center_m)


def _set_transform_op(xformable: UsdGeom.Xformable, matrix: np.ndarray, suffix: str) -> None:
    xformable.AddTransformOp(UsdGeom.XformOp.PrecisionDouble, suffix).Set(numpy_to_gf_matrix(matrix))


def _author_mesh(mesh: UsdGeom.Mesh, points: np.ndarray, face_counts: list[int], indices: list[int]) -> None:
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(points, dtype=np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray(face_counts))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(indices))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)


def _write_camera(stage: Usd.Stage, camera: PerspectiveCamera) -> None:
    usd_camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    if camera.to_world is not None:
        # Mitsuba's camera looks along +Z with +X left; USD's looks along −Z with +X right: flip X and Z.
        camera_to_world = np.asarray(camera.to_world) @ np.diag([-1.0, 1.0, -1.0, 1.0])
    else:
        assert camera.origin_m is not None and camera.target_m is not None  # guaranteed by the model
        forward = _unit(np.subtract(camera.target_m, camera.origin_m))
        right = _unit(np.cross(forward, camera.up))
        camera_to_world = _frame_matrix(right, np.cross(right, forward), -forward, camera.origin_m)
    _set_transform_op(usd_camera, camera_to_world, "hgCamera")
    sensor_width_mm = camera.sensor_width_mm or DEFAULT_SENSOR_WIDTH_MM
    focal_length_mm = camera.focal_length_mm or (
        sensor_width_mm / 2.0 / math.tan(math.radians(camera.horizontal_fov_deg()) / 2.0)
    )
    # USD lens attributes are in tenths of a scene unit; at 1 m per unit that is 100 mm per unit value.
    usd_camera.CreateHorizontalApertureAttr(sensor_width_mm / 100.0)
    usd_camera.CreateFocalLengthAttr(focal_length_mm / 100.0)
    usd_camera.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    usd_camera.CreateClippingRangeAttr(Gf.Vec2f(camera.near_clip_m, camera.far_clip_m))
    if camera.aperture_radius_m > 0.0:
        # A thin lens: N = f/(2a) with f in metres (the attribute's value / 10 at 1 m per unit); the focus
        # distance in scene units. fStop 0 (USD's default) is a pinhole.
        usd_camera.CreateFStopAttr(focal_length_mm / 1000.0 / (2.0 * camera.aperture_radius_m))
        usd_camera.CreateFocusDistanceAttr(camera.focus_distance())
    write_hg_attributes(usd_camera.GetPrim(), camera.model_dump(mode="json"))


#: USD ``UsdUVTexture`` wrap tokens of hgrender's wrap modes.
USD_WRAP = {"repeat": "repeat", "clamp": "clamp", "mirror": "mirror", "black": "black"}
#: USD ``sourceColorSpace`` tokens of hgrender's colour spaces.
USD_COLOUR_SPACE = {"auto": "auto", "srgb": "sRGB", "linear": "raw"}


def _write_uv_texture(stage: Usd.Stage, material: UsdShade.Material, texture: ImageTexture) -> Any:
    """A ``UsdUVTexture`` of ``texture`` reading the uv set through a ``UsdPrimvarReader_float2``; returns
    its ``rgb`` output (for a connection). Its scale/bias are hgrender's scale/offset; a ``uv_transform``
    is kept in the ``hg:`` attributes only."""
    path = material.GetPath()
    reader = UsdShade.Shader.Define(stage, path.AppendChild("TexCoordReader"))
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set(texture.uv_set)
    shader = UsdShade.Shader.Define(stage, path.AppendChild("DiffuseTexture"))
    shader.CreateIdAttr("UsdUVTexture")
    shader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(texture.path))
    shader.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    shader.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(USD_WRAP[texture.wrap_u])
    shader.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(USD_WRAP[texture.wrap_v])
    colour_space = USD_COLOUR_SPACE[texture.color_space]
    shader.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(colour_space)
    scale = np.broadcast_to(np.asarray(texture.scale, dtype=float), 3)
    offset = np.broadcast_to(np.asarray(texture.offset, dtype=float), 3)
    shader.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*scale.tolist(), 1.0))
    shader.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*offset.tolist(), 0.0))
    return shader.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)


def _write_preview_surface(stage: Usd.Stage, material: UsdShade.Material, model: Any) -> None:
    """A UsdPreviewSurface that approximates the hgrender material for display in DCC tools."""
    shader = UsdShade.Shader.Define(stage, material.GetPath().AppendChild("PreviewSurface"))
    shader.CreateIdAttr("UsdPreviewSurface")
    diffuse_rgb, metallic, roughness, opacity, ior = (0.5, 0.5, 0.5), 0.0, 0.5, 1.0, 1.5
    diffuse_texture = None
    if isinstance(model, DiffuseMaterial):
        reflectance = model.reflectance
        if isinstance(reflectance, ImageTexture):
            diffuse_texture = _write_uv_texture(stage, material, reflectance)
        elif isinstance(reflectance, float):
            diffuse_rgb = (reflectance,) * 3
        else:
            diffuse_rgb = reflectance_rgb(reflectance)
    elif isinstance(model, MirrorMaterial | RoughConductorMaterial | GratingMaterial):
        diffuse_rgb, metallic = CONDUCTOR_PREVIEW_RGB[model.conductor], 1.0
        roughness = 0.0 if isinstance(model, MirrorMaterial) else 0.3
    elif isinstance(model, ThinFilmMaterial):
        conductor = getattr(model.substrate, "conductor", None)
        diffuse_rgb = CONDUCTOR_PREVIEW_RGB[conductor] if conductor else (0.9, 0.9, 0.9)
        metallic, roughness = (1.0 if conductor else 0.0), 0.1
    elif isinstance(model, DielectricMaterial | RoughDielectricMaterial):
        opacity, roughness = 0.0, (0.0 if isinstance(model, DielectricMaterial) else 0.3)
        ior = model.ior if isinstance(model.ior, float) else 1.5
    diffuse = shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    diffuse.Set(Gf.Vec3f(*diffuse_rgb))
    if diffuse_texture is not None:
        diffuse.ConnectToSource(diffuse_texture)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(metallic)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(opacity)
    shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(ior)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")


def _write_materials(stage: Usd.Stage, scene: Scene) -> dict[str, UsdShade.Material]:
    UsdGeom.Scope.Define(stage, "/World/Materials")
    materials: dict[str, UsdShade.Material] = {}
    used_names: set[str] = set()
    for index, (material_id, model) in enumerate(scene.materials.items()):
        name = usd_prim_name(material_id, f"material_{index}")
        while name in used_names:
            name = f"{name}_{index}"
        used_names.add(name)
        material = UsdShade.Material.Define(stage, f"/World/Materials/{name}")
        prim = material.GetPrim()
        prim.CreateAttribute(MATERIAL_ID_ATTRIBUTE, Sdf.ValueTypeNames.String, custom=True).Set(material_id)
        write_hg_attributes(prim, model.model_dump(mode="json"))
        _write_preview_surface(stage, material, model)
        materials[material_id] = material
    return materials


def _write_texture_coordinates(mesh: UsdGeom.Mesh, name: str, uvs: np.ndarray) -> None:
    """Per-vertex texture coordinates as the ``texCoord2f[]`` primvar ``name`` (USD's ``st`` convention:
    origin at the image's bottom-left, v up — hgrender's)."""
    primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        name, Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    primvar.Set(Vt.Vec2fArray.FromNumpy(np.asarray(uvs, dtype=np.float32)))


def _write_shape(stage: Usd.Stage, path: str, shape: Any) -> UsdGeom.Xformable:
    if isinstance(shape, SphereShape):
        geometry: UsdGeom.Xformable = UsdGeom.Sphere.Define(stage, path)
        geometry.CreateRadiusAttr(shape.radius_m)
        placement = _frame_matrix(np.eye(3)[0], np.eye(3)[1], np.eye(3)[2], shape.center_m)
    elif isinstance(shape, CylinderShape):
        geometry = UsdGeom.Cylinder.Define(stage, path)
        geometry.CreateRadiusAttr(shape.radius_m)
        geometry.CreateHeightAttr(math.dist(shape.p0_m, shape.p1_m))
        geometry.CreateAxisAttr(UsdGeom.Tokens.z)
        placement = _axis_frame(shape.p0_m, shape.p1_m, axis_column=2)
    elif isinstance(shape, RectangleShape):
        geometry = UsdGeom.Mesh.Define(stage, path)
        placement = _rectangle_frame(shape.center_m, shape.normal, shape.up)
        half_w, half_h = shape.width_m / 2.0, shape.height_m / 2.0
        # Counter-clockwise seen from the normal side (local −Z) in a right-handed mesh.
        corners = [
            [-half_w, -half_h, 0.0],
            [-half_w, half_h, 0.0],
            [half_w, half_h, 0.0],
            [half_w, -half_h, 0.0],
        ]
        _author_mesh(geometry, np.asarray(corners), [4], [0, 1, 2, 3])
    elif isinstance(shape, DiskShape):
        geometry = UsdGeom.Mesh.Define(stage, path)
        placement = _rectangle_frame(shape.center_m, shape.normal, _any_perpendicular(_unit(shape.normal)))
        angles = -2.0 * math.pi * np.arange(DISK_POLYGON_SIDES) / DISK_POLYGON_SIDES
        ring = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1) * shape.radius_m
        _author_mesh(geometry, ring, [DISK_POLYGON_SIDES], list(range(DISK_POLYGON_SIDES)))
    elif isinstance(shape, MeshShape):
        geometry = UsdGeom.Mesh.Define(stage, path)
        placement = np.eye(4)
        flat_indices = [int(i) for triangle in shape.indices for i in triangle]
        _author_mesh(geometry, np.asarray(shape.vertices_m), [3] * len(shape.indices), flat_indices)
        if shape.normals is not None:
            geometry.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(shape.normals, dtype=np.float32)))
            geometry.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        for name, uvs in shape.texture_coordinate_sets().items():
            _write_texture_coordinates(geometry, name, np.asarray(uvs))
    elif isinstance(shape, PROCEDURAL_SHAPE_TYPES):
        geometry = UsdGeom.Mesh.Define(stage, path)
        placement = np.eye(4)
        generated = generate_mesh(shape)
        _author_mesh(
            geometry,
            generated.vertices_m,
            [3] * len(generated.triangles),
            generated.triangles.ravel().tolist(),
        )
        geometry.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(generated.normals.astype(np.float32)))
        geometry.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        _write_texture_coordinates(geometry, "st", generated.uvs)
    elif isinstance(shape, MeshFileShape):
        geometry = UsdGeom.Xform.Define(stage, path)
        placement = np.eye(4)
    else:
        raise TypeError(f"shape: unsupported type {type(shape).__name__}")
    if shape.transform is not None:
        _set_transform_op(geometry, np.asarray(shape.transform.to_matrix()), "hgTransform")
    if not np.array_equal(placement, np.eye(4)):
        _set_transform_op(geometry, placement, "hgPlacement")
    return geometry


def _write_emitter(stage: Usd.Stage, path: str, emitter: Any, scene: Scene) -> None:
    if isinstance(emitter, EnvironmentEmitter | SunEmitter):
        _write_light_at_infinity(stage, path, emitter, scene)
        return
    if isinstance(emitter, SphereEmitter):
        light: Any = UsdLux.SphereLight.Define(stage, path)
        light.CreateRadiusAttr(emitter.radius_m)
        light.CreateTreatAsPointAttr(False)
        placement = _frame_matrix(np.eye(3)[0], np.eye(3)[1], np.eye(3)[2], emitter.center_m)
    elif isinstance(emitter, CylinderEmitter):
        light = UsdLux.CylinderLight.Define(stage, path)
        light.CreateRadiusAttr(emitter.radius_m)
        light.CreateLengthAttr(math.dist(emitter.p0_m, emitter.p1_m))
        light.CreateTreatAsLineAttr(False)
        placement = _axis_frame(emitter.p0_m, emitter.p1_m, axis_column=0)
    elif isinstance(emitter, RectangleEmitter):
        light = UsdLux.RectLight.Define(stage, path)
        light.CreateWidthAttr(emitter.width_m)
        light.CreateHeightAttr(emitter.height_m)
        placement = _rectangle_frame(emitter.center_m, emitter.normal, emitter.up)
    elif isinstance(emitter, DiskEmitter):
        light = UsdLux.DiskLight.Define(stage, path)
        light.CreateRadiusAttr(emitter.radius_m)
        placement = _rectangle_frame(
            emitter.center_m, emitter.normal, _any_perpendicular(_unit(emitter.normal))
        )
    else:
        raise TypeError(f"emitter: unsupported type {type(emitter).__name__}")
    _set_transform_op(light, placement, "hgPlacement")
    film = scene.film
    radiance_scale = emitter_radiance_scale(emitter, film.wavelength_min_nm, film.wavelength_max_nm)
    light.CreateIntensityAttr(radiance_scale * luminance_per_radiance_scale(emitter.spectrum))
    light.CreateExposureAttr(0.0)
    light.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    light.CreateNormalizeAttr(False)
    write_hg_attributes(light.GetPrim(), emitter.model_dump(mode="json"))


def _write_light_at_infinity(stage: Usd.Stage, path: str, emitter: Any, scene: Scene) -> None:
    """An environment as a ``DomeLight`` (lat-long image or a constant colour) and a sun as a
    ``DistantLight`` whose local −Z points away from the sun, ``inputs:angle`` its angular diameter;
    ``inputs:intensity``: the luminance in nits of an untinted radiance c (an image's (1, 1, 1) texel, a
    constant dome's spectrum, the sun's disk)."""
    film = scene.film
    radiance_scale = emitter_radiance_scale(emitter, film.wavelength_min_nm, film.wavelength_max_nm)
    if isinstance(emitter, EnvironmentEmitter):
        light: Any = UsdLux.DomeLight.Define(stage, path)
        if emitter.path is not None:
            light.CreateTextureFileAttr(Sdf.AssetPath(emitter.path))
            light.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
            nits = radiance_scale * luminance_per_radiance_scale(ConstantSpectrum(type="constant", value=1.0))
        else:
            nits = radiance_scale * luminance_per_radiance_scale(emitter.spectrum)
        if emitter.transform is not None:
            rotation = np.eye(4)
            rotation[:3, :3] = np.asarray(emitter.transform.to_matrix())[:3, :3]
            _set_transform_op(light, rotation, "hgPlacement")
    else:
        light = UsdLux.DistantLight.Define(stage, path)
        light.CreateAngleAttr(emitter.angular_diameter_deg)
        towards_sun = _unit(emitter.direction)
        x_axis = _any_perpendicular(towards_sun)
        frame = _frame_matrix(x_axis, np.cross(towards_sun, x_axis), towards_sun, [0.0, 0.0, 0.0])
        _set_transform_op(light, frame, "hgPlacement")
        nits = radiance_scale * luminance_per_radiance_scale(emitter.spectrum)
    light.CreateIntensityAttr(nits)
    light.CreateExposureAttr(0.0)
    light.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    write_hg_attributes(light.GetPrim(), emitter.model_dump(mode="json"))


def build_stage(scene: Scene, stage: Usd.Stage) -> None:
    """Author ``scene`` into an empty ``stage``."""
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetMetadata(
        "customLayerData",
        {
            LAYER_DATA_KEY: {
                "schema": scene.schema_,
                "name": scene.name,
                "film": scene.film.model_dump(mode="json"),
            }
        },
    )
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    _write_camera(stage, scene.camera)
    materials = _write_materials(stage, scene)
    UsdGeom.Scope.Define(stage, "/World/Shapes")
    for index, shape in enumerate(scene.shapes):
        geometry = _write_shape(stage, f"/World/Shapes/shape_{index:04d}", shape)
        prim = geometry.GetPrim()
        # Texture coordinates travel as primvars (``_write_texture_coordinates``), not as hg: attributes.
        write_hg_attributes(prim, shape.model_dump(mode="json", exclude={"material", "uvs", "uv_sets"}))
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(materials[shape.material])
    UsdGeom.Scope.Define(stage, "/World/Lights")
    for index, emitter in enumerate(scene.emitters):
        _write_emitter(stage, f"/World/Lights/light_{index:04d}", emitter, scene)


def scene_to_usd(scene: Scene, path: str | os.PathLike[str]) -> Path:
    """Write ``scene`` to ``path`` (``.usda``/``.usdc``/``.usd``/``.usdz``) atomically; return the path."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in USD_SUFFIXES:
        raise InputError(f"path must end with one of {', '.join(USD_SUFFIXES)}, got {target.name!r}")
    stage = Usd.Stage.CreateInMemory()
    build_stage(scene, stage)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=f".{target.name}.") as scratch:
        layer_path = Path(scratch) / ("scene.usdc" if suffix == ".usdz" else f"scene{suffix}")
        if not stage.GetRootLayer().Export(str(layer_path)):
            raise OSError(f"path: USD could not write {layer_path}")
        if suffix == ".usdz":
            package_path = Path(scratch) / "scene.usdz"
            if not UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(layer_path)), str(package_path)):
                raise OSError(f"path: USD could not package {target.name}")
            layer_path = package_path
        os.replace(layer_path, target)
    return target
