"""Compile a validated ``schemas.scene.Scene`` into a Mitsuba scene plus the tables ``hg_path`` reads.

Two Mitsuba dictionaries come out of one scene: the one ``hg_path`` renders (geometry, sensor, area
emitters; its BSDFs are ignored) and a *reference* one whose shapes carry Mitsuba's own BSDFs, used to
check ``hg_path`` against Mitsuba's ``path`` integrator on scenes without coherence-sensitive materials.
Emitter surfaces absorb in both.

Emitter radiometry (docs/scenes.md): L(λ) = c·s(λ) W·m⁻²·sr⁻¹·nm⁻¹, Lambertian; with ``power_w`` P,
c = P / (π·A·∫_{λmin}^{λmax} s dλ) over the film's wavelength range (A the emitting area in m²).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.artifacts.layout import BandLayout
from hgcore.errors import InputError
from hgcore.optics import ior as ior_data
from hgcore.optics.grating import BinaryGrating
from hgcore.optics.rgb_upsampling import fit_coefficients, sigmoid_polynomial
from hgcore.optics.rough_surface import RoughSurface
from hgcore.settings import SceneLimits
from schemas import scene as model
from schemas.errors import json_pointer
from schemas.photometry import emitter_radiance_scale, evaluate_spectrum
from schemas.procedural import GENERATORS, generate_mesh
from schemas.textures import ImageHeader, check_scene_images
from worker.render import materials as mat
from worker.render.emitters import FAR_DISTANCE_M, EmitterGeometry, EmitterKind, EmitterTable
from worker.render.spectral import SpectralTable, grid_wavelengths_nm
from worker.render.textures import TextureTable, coefficient_table, decode_image, uv_affine
from worker.render.thin_lens import ThinLens

EMITTER_SPECTRUM_STEP_NM = 1.0
SUN_DISTANCE_M = FAR_DISTANCE_M
"""How far a ``sun`` is placed: a sphere of radius D·sin α at D along its direction subtends the sun's
angular radius α from the origin. From a point x of the scene its centre is off by at most |x|/D: 1e-5 rad
at 10 m, 0.2 % of the sun's 4.6e-3 rad, and float32 keeps the sphere's surface to ~0.1 m of its 4.6 km
radius (docs/physics.md §9)."""
#: Ranges (SI) that textured values are clipped to: film thickness, RMS roughness, correlation length.
TEXTURE_RANGES_SI = {
    mat.FILM_THICKNESS_M: (0.0, model.MAX_FILM_THICKNESS_UM * 1e-6),
    mat.ROUGHNESS_RMS_M: (0.0, model.MAX_ROUGHNESS_RMS_UM * 1e-6),
    mat.CORRELATION_LENGTH_M: (
        model.MIN_CORRELATION_LENGTH_UM * 1e-6,
        model.MAX_CORRELATION_LENGTH_UM * 1e-6,
    ),
}


@dataclass
class CompiledScene:
    scene: model.Scene
    mitsuba_dict: dict[str, Any]
    reference_dict: dict[str, Any]
    bands: BandLayout
    material_table: mat.MaterialTable
    spectral_table: SpectralTable
    emitter_table: EmitterTable
    shape_materials: dict[str, int]  # Mitsuba shape id -> material index
    emitter_records: dict[str, int]  # Mitsuba shape id of an emitter -> emitter record index
    #: the textures' bindings (None: the scene has none)
    texture_table: TextureTable | None = None
    #: the environment emitter's record index (None: no environment)
    environment_record: int | None = None
    lens: ThinLens | None = None  # the camera's thin lens (None: a pinhole)


def spectrum_on(spectrum: Any, wavelengths_nm: np.ndarray) -> np.ndarray:
    """A scene spectrum (or a plain number) at ``wavelengths_nm``, normalised as in docs/scenes.md."""
    if isinstance(spectrum, int | float):
        return np.full(wavelengths_nm.shape, float(spectrum))
    return evaluate_spectrum(spectrum, wavelengths_nm)


def _ior_on_grid(ior: float | str, grid_nm: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """(n, κ, dispersive) of a real index or a named material on the grid (end values held outside)."""
    if isinstance(ior, int | float):
        return np.full(grid_nm.shape, float(ior)), np.zeros(grid_nm.shape), False
    rows = ior_data.ior_table(ior, grid_nm)
    return rows[:, 1], rows[:, 2], True


def _normalized(vector: list[float]) -> np.ndarray:
    array = np.asarray(vector, dtype=float)
    return array / np.linalg.norm(array)


def _frame_matrix(
    center: list[float], normal: list[float], up: list[float] | None, half_x: float, half_y: float
) -> list[list[float]]:
    """to_world of Mitsuba's [-1,1]² rectangle/disk: z → normal, y → up, scaled by the half extents."""
    n = _normalized(normal)
    if up is None:
        helper = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        up_vector = helper - np.dot(helper, n) * n
    else:
        up_vector = np.asarray(up, dtype=float) - np.dot(up, n) * n
    y_axis = up_vector / np.linalg.norm(up_vector)
    x_axis = np.cross(y_axis, n)
    matrix = np.eye(4)
    matrix[:3, 0] = x_axis * half_x
    matrix[:3, 1] = y_axis * half_y
    matrix[:3, 2] = n
    matrix[:3, 3] = center
    return matrix.tolist()


def _compose(mi: Any, transform: model.Transform | None, own: list[list[float]] | None) -> Any:
    matrix = np.eye(4) if own is None else np.asarray(own)
    if transform is not None:
        matrix = np.asarray(transform.to_matrix()) @ matrix
    return mi.ScalarTransform4f(matrix.tolist())


class SceneCompiler:
    """Builds ``CompiledScene`` objects; ``bundle_dir`` resolves mesh files of uploaded bundles;
    ``limits`` (the process's settings, never re-read from the environment here) bound the images the
    scene reads."""

    def __init__(self, mi: Any, bundle_dir: Path | None = None, *, limits: SceneLimits) -> None:
        self.mi = mi
        self.bundle_dir = bundle_dir
        self.limits = limits
        self.grid_nm = grid_wavelengths_nm()
        # Per compile: the images the scene reads (checked from their headers), decoded on first use.
        self._images: dict[str, tuple[Path, ImageHeader]] = {}
        self._decoded: dict[tuple[str, str], np.ndarray] = {}
        self._textures = TextureTable()

    # ------------------------------------------------------------------ textures
    def _image(self, path: str, colour_space: str) -> np.ndarray:
        """The bundle image ``path`` as float32 RGBA, decoded once per colour space."""
        key = (path, colour_space)
        if key not in self._decoded:
            file, header = self._images[path]
            self._decoded[key] = decode_image(file, header, colour_space)
        return self._decoded[key]

    def _scalar_texture(
        self,
        record_values: dict[int, float],
        ranges: dict[int, tuple[float, float]],
        offset: int,
        value: Any,
        unit: float,
    ) -> None:
        """Parameter ``offset`` of a record: a number (× ``unit`` into SI) or a texture, whose binding goes
        to the record and whose mean value stands in for the constant (the Mitsuba reference's, and the
        rough-surface model's where only the other parameter is textured)."""
        if not isinstance(value, model.ImageTexture):
            record_values[offset] = value * unit
            return
        low, high = TEXTURE_RANGES_SI[offset]
        image = self._image(value.path, value.color_space)
        binding, smallest, largest = self._textures.add_scalar(value, image, unit, low, high)
        record_values[mat.TEXTURE_BINDINGS[offset]] = binding + 1.0
        ranges[offset] = (smallest, largest)
        record_values[offset] = max(0.5 * (smallest + largest), low if low > 0.0 else 1e-12)

    def _colour_texture(
        self, values: dict[int, float], offset: int, texture: model.ImageTexture, spectra: SpectralTable
    ) -> np.ndarray:
        """A colour parameter from a texture: its binding, and its mean colour's spectrum as the constant
        (what a lane without texture coordinates would read). Returns the texture's linear sRGB."""
        if self._textures.coefficients is None:
            self._textures.coefficients = coefficient_table()
        image = self._image(texture.path, texture.color_space)
        binding, rgb = self._textures.add_colour(texture, image)
        values[mat.TEXTURE_BINDINGS[offset]] = binding + 1.0
        mean_rgb = rgb.reshape(-1, 3).mean(axis=0, dtype=np.float64)[None]
        c = fit_coefficients(mean_rgb, self._textures.coefficients)[0]
        values[offset] = spectra.add(sigmoid_polynomial((c[0], c[1], c[2]), self.grid_nm))
        return rgb

    # ------------------------------------------------------------------ materials
    def _material_record(self, material: Any, spectra_table: SpectralTable) -> tuple[mat.MaterialRow, dict]:
        grid = self.grid_nm
        values: dict[int, float] = {}
        ranges: dict[int, tuple[float, float]] = {}
        if getattr(material, "scattering_region_radius_m", None) is not None:
            values[mat.SCATTERING_REGION_RADIUS_M] = material.scattering_region_radius_m

        def record(kind: mat.MaterialKind, surface: Any = None) -> mat.MaterialRow:
            return mat.MaterialRow(kind, values, surface, ranges)

        def tint(m: Any) -> None:
            if isinstance(m.tint, model.ImageTexture):
                self._colour_texture(values, mat.TINT_ID, m.tint, spectra_table)
            elif m.tint is not None:
                values[mat.TINT_ID] = spectra_table.add(np.clip(spectrum_on(m.tint, grid), 0, 1))

        def conductor(name: str) -> None:
            n, kappa, _ = _ior_on_grid(name, grid)
            values[mat.ETA_ID] = spectra_table.add(n)
            values[mat.KAPPA_ID] = spectra_table.add(kappa)

        def dielectric(ior: float | str, key: int = mat.ETA_ID) -> None:
            n, _, dispersive = _ior_on_grid(ior, grid)
            values[key] = spectra_table.add(n)
            values[mat.KAPPA_ID] = spectra_table.add_constant(0.0)
            values[mat.DISPERSIVE] = float(dispersive)

        def rough(m: Any) -> RoughSurface:
            self._scalar_texture(values, ranges, mat.ROUGHNESS_RMS_M, m.roughness_rms_um, 1e-6)
            self._scalar_texture(values, ranges, mat.CORRELATION_LENGTH_M, m.correlation_length_um, 1e-6)
            return RoughSurface(
                values[mat.ROUGHNESS_RMS_M], values[mat.CORRELATION_LENGTH_M], m.psd, m.psd_exponent
            )

        kind = material.type
        if kind == "diffuse":
            if isinstance(material.reflectance, model.ImageTexture):
                rgb = self._colour_texture(values, mat.REFLECTANCE_ID, material.reflectance, spectra_table)
                reflectance_reference = self._mitsuba_bitmap(material.reflectance, rgb)
            else:
                values[mat.REFLECTANCE_ID] = spectra_table.add(
                    np.clip(spectrum_on(material.reflectance, grid), 0, 1)
                )
                reflectance_reference = self._mitsuba_spectrum(material.reflectance, clip=True)
            return record(mat.MaterialKind.DIFFUSE), {"type": "diffuse", "reflectance": reflectance_reference}
        if kind == "mirror":
            tint(material)
            if material.conductor == "perfect":
                values[mat.ETA_ID] = spectra_table.add_constant(0.0)
                values[mat.KAPPA_ID] = spectra_table.add_constant(1e6)  # |r| = 1 at every angle
                reference = {"type": "conductor", "material": "none"}
            else:
                conductor(material.conductor)
                reference = {"type": "conductor", "material": material.conductor}
            return record(mat.MaterialKind.MIRROR), reference
        if kind == "dielectric":
            dielectric(material.ior)
            values[mat.EXTERIOR_IOR] = material.exterior_ior
            ior_value = (
                material.ior
                if isinstance(material.ior, float)
                else float(ior_data.spectral_ior(material.ior, 550.0)[0])
            )
            return record(mat.MaterialKind.DIELECTRIC), {
                "type": "dielectric",
                "int_ior": ior_value,
                "ext_ior": material.exterior_ior,
            }
        placeholder = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}
        if kind == "rough_conductor":
            conductor(material.conductor)
            tint(material)
            return record(mat.MaterialKind.ROUGH_CONDUCTOR, rough(material)), placeholder
        if kind == "rough_dielectric":
            dielectric(material.ior)
            values[mat.EXTERIOR_IOR] = material.exterior_ior
            return record(mat.MaterialKind.ROUGH_DIELECTRIC, rough(material)), placeholder
        if kind == "thin_film":
            self._scalar_texture(values, ranges, mat.FILM_THICKNESS_M, material.film_thickness_um, 1e-6)
            values[mat.FILM_IOR_ID] = spectra_table.add(_ior_on_grid(material.film_ior, grid)[0])
            values[mat.BEAMS] = float(material.beams)
            if material.film_extinction > 0.0:
                values[mat.FILM_EXTINCTION] = material.film_extinction
            if hasattr(material.substrate, "conductor"):
                conductor(material.substrate.conductor)
            else:
                dielectric(material.substrate.ior)
                values[mat.FILM_TRANSMITS] = 1.0
            return record(mat.MaterialKind.THIN_FILM, rough(material)), placeholder
        if kind == "grating":
            conductor(material.conductor)
            values[mat.ORIENTATION_RAD] = math.radians(material.orientation_deg)
            grating = BinaryGrating(
                pitch_x_m=material.pitch_um * 1e-6,
                pitch_y_m=None if material.pitch_y_um is None else material.pitch_y_um * 1e-6,
                duty_cycle=material.duty,
                depth_m=material.pit_depth_nm * 1e-9,
                pit_ior=material.pit_ior,
                lobe_width_per_um=material.lobe_width_per_um,
                max_order=max(material.max_order, 1),
            )
            return record(mat.MaterialKind.GRATING, grating), placeholder
        raise InputError(f"materials: type {kind!r} is not supported by the renderer")

    def _mitsuba_bitmap(self, texture: model.ImageTexture, rgb: np.ndarray) -> dict[str, Any]:
        """The texture as Mitsuba's ``bitmap`` (for the reference scene): the same linear sRGB (after
        scale/offset), upsampled by Mitsuba's own table; Mitsuba's v runs down the image, hence the flip in
        ``to_uv``. Mitsuba has one wrap mode for both axes and no ``black``: other textures fall back to
        their mean colour."""
        mi = self.mi
        affine = np.asarray(uv_affine(texture)[:6]).reshape(2, 3)
        if texture.wrap_u != texture.wrap_v or texture.wrap_u == "black":
            return {"type": "rgb", "value": rgb.reshape(-1, 3).mean(axis=0).tolist()}
        # Mitsuba looks up (u', 1 − v') for our uv' = A·(u, v, 1) (its si.uv is ours: see _shape_dict).
        flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]])
        to_uv = flip @ np.vstack([affine, [0.0, 0.0, 1.0]])
        matrix = np.eye(4)
        matrix[:2, :2], matrix[:2, 3] = to_uv[:2, :2], to_uv[:2, 2]
        return {
            "type": "bitmap",
            "bitmap": mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32)),
            "raw": False,
            "filter_type": texture.filter,
            "wrap_mode": texture.wrap_u,
            "to_uv": mi.ScalarTransform4f(matrix.tolist()),
        }

    def _mitsuba_spectrum(self, spectrum: Any, clip: bool = False) -> dict[str, Any]:
        wavelengths = np.arange(300.0, 1000.0 + EMITTER_SPECTRUM_STEP_NM, EMITTER_SPECTRUM_STEP_NM)
        values = spectrum_on(spectrum, wavelengths)
        if clip:
            values = np.clip(values, 0.0, 1.0)
        return {
            "type": "regular",
            "wavelength_min": float(wavelengths[0]),
            "wavelength_max": float(wavelengths[-1]),
            "values": ",".join(f"{v:.9g}" for v in values),
        }

    # ------------------------------------------------------------------ geometry
    def _shape_dict(self, shape: Any, uv_set: str = "st") -> dict[str, Any]:
        mi = self.mi
        kind = shape.type
        if kind == "sphere":
            own = np.eye(4)
            own[:3, :3] *= shape.radius_m
            own[:3, 3] = shape.center_m
            return {"type": "sphere", "to_world": _compose(mi, shape.transform, own.tolist())}
        if kind == "cylinder":
            p0, p1 = np.asarray(shape.p0_m), np.asarray(shape.p1_m)
            axis = p1 - p0
            length = float(np.linalg.norm(axis))
            own = np.asarray(
                _frame_matrix(p0.tolist(), (axis / length).tolist(), None, shape.radius_m, shape.radius_m)
            )
            own[:3, 2] *= length
            return {"type": "cylinder", "to_world": _compose(mi, shape.transform, own.tolist())}
        if kind == "rectangle":
            own = _frame_matrix(shape.center_m, shape.normal, shape.up, shape.width_m / 2, shape.height_m / 2)
            return {"type": "rectangle", "to_world": _compose(mi, shape.transform, own)}
        if kind == "disk":
            own = _frame_matrix(shape.center_m, shape.normal, None, shape.radius_m, shape.radius_m)
            return {"type": "disk", "to_world": _compose(mi, shape.transform, own)}
        if kind == "mesh" or kind in GENERATORS:
            return self._inline_mesh(shape, uv_set)
        if kind == "mesh_file":
            if self.bundle_dir is None:
                raise InputError(f"shapes: mesh file {shape.path!r} needs an uploaded bundle")
            path = (self.bundle_dir / shape.path).resolve()
            if self.bundle_dir.resolve() not in path.parents:
                raise InputError(f"shapes: mesh file {shape.path!r} escapes the bundle")
            mesh = {
                "type": path.suffix.lstrip(".").lower(),
                "filename": str(path),
                "to_world": _compose(mi, shape.transform, None),
            }
            if mesh["type"] == "obj":
                # Keep the file's (u, v), origin bottom-left (hgrender's convention, schemas.scene):
                # Mitsuba's OBJ loader stores (u, 1 − v) unless told not to.
                mesh["flip_tex_coords"] = False
            return mesh
        raise InputError(f"shapes: type {kind!r} is not supported by the renderer")

    def _inline_mesh(self, shape: Any, uv_set: str = "st") -> Any:
        """An ``mi.Mesh`` of an inline or procedural mesh, the shape's transform applied to its vertices.

        Procedural meshes carry texture coordinates: Mitsuba's first shading tangent follows ∂p/∂u, which
        is what orients anisotropic materials (an optical disc's concentric grating tracks). An inline
        mesh carries its set ``uv_set`` (the one its material's textures read), if it has it.
        """
        mi = self.mi
        if shape.type == "mesh":
            vertices = np.asarray(shape.vertices_m, dtype=np.float64)
            faces = np.asarray(shape.indices, dtype=np.uint32)
            normals = None if shape.normals is None else np.asarray(shape.normals, dtype=np.float64)
            sets = shape.texture_coordinate_sets()
            uvs = np.asarray(sets[uv_set], dtype=np.float64) if uv_set in sets else None
        else:
            generated = generate_mesh(shape)
            vertices, faces = generated.vertices_m, generated.triangles.astype(np.uint32)
            normals, uvs = generated.normals, generated.uvs
        if shape.transform is not None:
            matrix = np.asarray(shape.transform.to_matrix())
            vertices = vertices @ matrix[:3, :3].T + matrix[:3, 3]
            if normals is not None:  # normals transform by the inverse transpose
                normals = normals @ np.linalg.inv(matrix[:3, :3])
                normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        mesh = mi.Mesh(
            "inline",
            vertex_count=len(vertices),
            face_count=len(faces),
            has_vertex_normals=normals is not None,
            has_vertex_texcoords=uvs is not None,
        )
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(vertices.astype(np.float32).ravel())
        params["faces"] = mi.UInt32(faces.ravel())
        if normals is not None:
            params["vertex_normals"] = mi.Float(normals.astype(np.float32).ravel())
        if uvs is not None:
            params["vertex_texcoords"] = mi.Float(uvs.astype(np.float32).ravel())
        params.update()
        return mesh

    def _emitter(self, emitter: Any, film: model.Film) -> tuple[dict[str, Any], EmitterGeometry, float]:
        """Mitsuba shape dict (without the emitter), the coherence record and the emitting area (m²)."""
        kind = emitter.type
        if kind == "sphere":
            record = EmitterGeometry(EmitterKind.SPHERE, tuple(emitter.center_m), radius_m=emitter.radius_m)
            shape = {"type": "sphere", "center": list(emitter.center_m), "radius": emitter.radius_m}
            return shape, record, 4 * math.pi * emitter.radius_m**2
        if kind == "cylinder":
            p0, p1 = np.asarray(emitter.p0_m), np.asarray(emitter.p1_m)
            length = float(np.linalg.norm(p1 - p0))
            record = EmitterGeometry(
                EmitterKind.CYLINDER,
                tuple(((p0 + p1) / 2).tolist()),
                axis=tuple(((p1 - p0) / length).tolist()),
                radius_m=emitter.radius_m,
                length_m=length,
            )
            shape = {"type": "cylinder", "p0": p0.tolist(), "p1": p1.tolist(), "radius": emitter.radius_m}
            return shape, record, 2 * math.pi * emitter.radius_m * length
        if kind == "rectangle":
            normal = _normalized(emitter.normal)
            up = np.asarray(emitter.up, dtype=float) - np.dot(emitter.up, normal) * normal
            up /= np.linalg.norm(up)
            record = EmitterGeometry(
                EmitterKind.RECTANGLE,
                tuple(emitter.center_m),
                axis=tuple(normal.tolist()),
                up=tuple(up.tolist()),
                width_m=emitter.width_m,
                height_m=emitter.height_m,
            )
            own = _frame_matrix(
                emitter.center_m, emitter.normal, emitter.up, emitter.width_m / 2, emitter.height_m / 2
            )
            shape = {"type": "rectangle", "to_world": self.mi.ScalarTransform4f(own)}
            return shape, record, emitter.width_m * emitter.height_m
        if kind == "disk":
            normal = _normalized(emitter.normal)
            record = EmitterGeometry(
                EmitterKind.DISK,
                tuple(emitter.center_m),
                axis=tuple(normal.tolist()),
                radius_m=emitter.radius_m,
            )
            own = _frame_matrix(emitter.center_m, emitter.normal, None, emitter.radius_m, emitter.radius_m)
            shape = {"type": "disk", "to_world": self.mi.ScalarTransform4f(own)}
            return shape, record, math.pi * emitter.radius_m**2
        if kind == "sun":
            # A sphere at SUN_DISTANCE_M subtending the sun's angular radius α: Mitsuba samples its cone and
            # the integrator its stable solid angle; its coherence is the sphere's, a uniform disk of angular
            # radius α (Σ⊥/r² = sin²α/4: ℓ = 2/(k sin α)).
            direction = _normalized(emitter.direction)
            half_angle = math.radians(emitter.angular_diameter_deg) / 2.0
            radius = SUN_DISTANCE_M * math.sin(half_angle)
            center = tuple((direction * SUN_DISTANCE_M).tolist())
            record = EmitterGeometry(EmitterKind.SPHERE, center, radius_m=radius)
            shape = {"type": "sphere", "center": list(center), "radius": radius}
            return shape, record, 4 * math.pi * radius**2
        raise InputError(f"emitters: type {kind!r} is not supported by the renderer")

    def _environment(self, emitter: model.EnvironmentEmitter, index: int) -> dict[str, Any]:
        """Mitsuba's ``constant`` (L = c·s(λ)) or ``envmap`` (lat-long, importance-sampled by its
        luminance × sin θ; RGB upsampled × D65) emitter of the environment, turned by its transform."""
        mi = self.mi
        to_world = np.eye(4)
        if emitter.transform is not None:
            to_world[:3, :3] = np.asarray(emitter.transform.to_matrix())[:3, :3]
        if emitter.path is None:
            return {
                "type": "constant",
                "radiance": self._radiance_values(emitter.spectrum, emitter.radiance_scale),
            }
        rgba = self._image(emitter.path, "auto")
        if not np.all(np.isfinite(rgba[..., :3])) or np.any(rgba[..., :3] < 0.0):
            raise InputError(f"/emitters/{index}/path: the image has negative or non-finite values")
        return {
            "type": "envmap",
            "bitmap": mi.Bitmap(np.ascontiguousarray(rgba[..., :3], dtype=np.float32)),
            "scale": emitter.radiance_scale,
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
        }

    def _radiance_values(self, spectrum: Any, scale: float) -> dict[str, Any]:
        wavelengths = np.arange(200.0, 2500.0 + EMITTER_SPECTRUM_STEP_NM, EMITTER_SPECTRUM_STEP_NM)
        values = spectrum_on(spectrum, wavelengths)
        return {
            "type": "regular",
            "wavelength_min": float(wavelengths[0]),
            "wavelength_max": float(wavelengths[-1]),
            "values": ",".join(f"{v * scale:.9g}" for v in values),
        }

    def _radiance(self, emitter: Any, area_m2: float, film: model.Film) -> dict[str, Any]:
        wavelengths = np.arange(200.0, 2500.0 + EMITTER_SPECTRUM_STEP_NM, EMITTER_SPECTRUM_STEP_NM)
        values = spectrum_on(emitter.spectrum, wavelengths)
        if isinstance(emitter, model.SunEmitter):
            scale = emitter_radiance_scale(emitter, film.wavelength_min_nm, film.wavelength_max_nm)
        elif emitter.power_w is not None:
            inside = (wavelengths >= film.wavelength_min_nm) & (wavelengths <= film.wavelength_max_nm)
            integral = float(np.trapezoid(values[inside], wavelengths[inside]))
            if integral <= 0:
                raise InputError("emitters: spectrum integrates to zero over the film's wavelength range")
            scale = emitter.power_w / (math.pi * area_m2 * integral)
        else:
            scale = emitter.radiance_scale
        return self._radiance_values(emitter.spectrum, scale)

    # ------------------------------------------------------------------ whole scene
    def compile(self, scene: model.Scene) -> CompiledScene:
        mi = self.mi
        film = scene.film
        camera = scene.camera
        self._images = check_scene_images(scene, self.bundle_dir, self.limits)
        self._decoded, self._textures = {}, TextureTable()
        if camera.to_world is not None:
            camera_to_world = mi.ScalarTransform4f(camera.to_world)
        else:
            camera_to_world = mi.ScalarTransform4f().look_at(
                origin=camera.origin_m, target=camera.target_m, up=camera.up
            )
        far_clip = camera.far_clip_m
        if any(isinstance(emitter, model.SunEmitter) for emitter in scene.emitters):
            far_clip = max(far_clip, 2.0 * SUN_DISTANCE_M)  # the camera sees the sun's disk
        sensor = {
            "type": "perspective",
            "fov": camera.horizontal_fov_deg(),
            "fov_axis": "x",
            "near_clip": camera.near_clip_m,
            "far_clip": far_clip,
            "to_world": camera_to_world,
            "film": {
                "type": "hdrfilm",
                "width": film.width,
                "height": film.height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            "sampler": {"type": "independent", "sample_count": 1},
        }
        spectral_table = SpectralTable()
        material_table = mat.MaterialTable()
        material_index: dict[str, int] = {}
        references: dict[str, dict] = {}
        for name, material in scene.materials.items():
            record, reference = self._material_record(material, spectral_table)
            material_index[name] = material_table.add(record)
            references[name] = reference
        if material_table.tinted():  # every conductor then reads a tint: 1 where it has none
            for record in material_table.records:
                conductor = record.kind in (mat.MaterialKind.MIRROR, mat.MaterialKind.ROUGH_CONDUCTOR)
                if conductor and mat.TINT_ID not in record.values:
                    record.values[mat.TINT_ID] = spectral_table.add_constant(1.0)
        black_index = material_table.add(mat.MaterialRow(mat.MaterialKind.BLACK))

        # A thin lens: hg_path's renderer puts ``thin_lens.ThinLens`` on the pinhole sensor (a frozen pass
        # cannot record Mitsuba's ``thinlens``); the reference scene uses Mitsuba's own ``thinlens``.
        lens = None
        reference_sensor = sensor
        if camera.aperture_radius_m > 0.0:
            lens = self._thin_lens(camera, camera_to_world)
            reference_sensor = {
                **sensor,
                "type": "thinlens",
                "aperture_radius": lens.aperture_radius_m,
                "focus_distance": lens.focus_distance_m,
            }
        hg_dict: dict[str, Any] = {"type": "scene", "sensor": sensor}
        reference_dict: dict[str, Any] = {"type": "scene", "sensor": reference_sensor}
        shape_materials: dict[str, int] = {}
        for index, shape in enumerate(scene.shapes):
            key = f"shape_{index}"
            uv_set = _texture_uv_set(scene, shape, index)
            shape_dict = self._shape_dict(shape, uv_set)
            shape_materials[key] = material_index[shape.material]
            if isinstance(shape_dict, dict):
                hg_dict[key] = {**shape_dict, "bsdf": {"type": "diffuse"}}
                reference_dict[key] = {**shape_dict, "bsdf": references[shape.material]}
            else:  # an inline mi.Mesh instance; its id names it like the dictionary shapes
                shape_dict.set_id(key)
                hg_dict[key] = shape_dict
                reference = references[shape.material]
                reference_dict[key] = self._inline_mesh_with_bsdf(shape, reference, key, uv_set)
        emitter_table = EmitterTable()
        emitter_records: dict[str, int] = {}
        environment_record = None
        black = {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.0}}
        for index, emitter in enumerate(scene.emitters):
            if isinstance(emitter, model.EnvironmentEmitter):
                environment_record = len(emitter_table.records)
                emitter_table.records.append(EmitterGeometry(EmitterKind.ENVIRONMENT, (0.0, 0.0, 0.0)))
                hg_dict["environment"] = reference_dict["environment"] = self._environment(emitter, index)
                continue
            key = f"emitter_{index}"
            shape_dict, record, area = self._emitter(emitter, film)
            emitter_records[key] = len(emitter_table.records)
            emitter_table.records.append(record)
            shape_materials[key] = black_index
            full = {
                **shape_dict,
                "bsdf": black,
                "emitter": {"type": "area", "radiance": self._radiance(emitter, area, film)},
            }
            hg_dict[key] = full
            reference_dict[key] = full
        bands = BandLayout(film.wavelength_min_nm, film.wavelength_max_nm, film.bands)
        return CompiledScene(
            scene,
            hg_dict,
            reference_dict,
            bands,
            material_table,
            spectral_table,
            emitter_table,
            shape_materials,
            emitter_records,
            texture_table=self._textures if len(self._textures) else None,
            environment_record=environment_record,
            lens=lens,
        )

    def _thin_lens(self, camera: model.PerspectiveCamera, camera_to_world: Any) -> ThinLens:
        """The camera's thin lens in world space (``thin_lens``: Mitsuba's camera frame, +x left)."""
        mi = self.mi

        def axis(local: tuple[float, float, float]) -> tuple[float, float, float]:
            vector = np.asarray(camera_to_world @ mi.ScalarVector3f(*local), dtype=float)
            return tuple((vector / np.linalg.norm(vector)).tolist())

        return ThinLens(
            aperture_radius_m=camera.aperture_radius_m,
            focus_distance_m=camera.focus_distance(),
            near_clip_m=camera.near_clip_m,
            far_clip_m=camera.far_clip_m,
            centre=tuple(np.asarray(camera_to_world @ mi.ScalarPoint3f(0.0, 0.0, 0.0), dtype=float).tolist()),
            axis_x=axis((1.0, 0.0, 0.0)),
            axis_y=axis((0.0, 1.0, 0.0)),
            axis_z=axis((0.0, 0.0, 1.0)),
        )

    def _inline_mesh_with_bsdf(self, shape: Any, bsdf: dict, key: str, uv_set: str) -> Any:
        mesh = self._inline_mesh(shape, uv_set)
        mesh.set_id(key)
        mesh.set_bsdf(self.mi.load_dict(bsdf))
        return mesh


def _texture_uv_set(scene: model.Scene, shape: Any, index: int) -> str:
    """The texture coordinate set a shape's material's textures read (``st`` without textures); one per
    material, and a shape other than an inline mesh has only ``st``."""
    material = scene.materials[shape.material]
    textures = {
        name: getattr(material, name)
        for name in type(material).model_fields
        if isinstance(getattr(material, name), model.ImageTexture)
    }
    sets = {texture.uv_set for texture in textures.values()}
    if len(sets) > 1:
        pointer = json_pointer(["materials", shape.material])
        message = f"its textures read different uv sets {sorted(sets)}; use one per material"
        raise InputError(f"{pointer}: {message}")
    uv_set = sets.pop() if sets else "st"
    available = shape.texture_coordinate_sets() if isinstance(shape, model.MeshShape) else {"st": []}
    if textures and uv_set not in available:
        name = next(n for n, t in textures.items() if t.uv_set == uv_set)
        where = json_pointer(["materials", shape.material, name, "uv_set"])
        has = ", ".join(sorted(available)) or "none"
        raise InputError(f"{where}: shape /shapes/{index} has no uv set {uv_set!r} (it has: {has})")
    return uv_set
