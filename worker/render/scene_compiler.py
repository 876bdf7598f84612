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
from hgcore.optics.rough_surface import RoughSurface
from schemas import scene as model
from schemas.photometry import evaluate_spectrum
from schemas.procedural import GENERATORS, generate_mesh
from worker.render import materials as mat
from worker.render.emitters import EmitterKind, EmitterRecord, EmitterTable
from worker.render.spectral import SpectralTable, grid_wavelengths_nm
from worker.render.thin_lens import ThinLens

EMITTER_SPECTRUM_STEP_NM = 1.0


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
    """Builds ``CompiledScene`` objects; ``bundle_dir`` resolves mesh files of uploaded bundles."""

    def __init__(self, mi: Any, bundle_dir: Path | None = None) -> None:
        self.mi = mi
        self.bundle_dir = bundle_dir
        self.grid_nm = grid_wavelengths_nm()

    # ------------------------------------------------------------------ materials
    def _material_record(
        self, material: Any, spectra_table: SpectralTable
    ) -> tuple[mat.MaterialRecord, dict]:
        grid = self.grid_nm
        values: dict[int, float] = {}
        if getattr(material, "scattering_region_radius_m", None) is not None:
            values[mat.SCATTERING_REGION_RADIUS_M] = material.scattering_region_radius_m

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
            values[mat.ROUGHNESS_RMS_M] = m.roughness_rms_um * 1e-6
            values[mat.CORRELATION_LENGTH_M] = m.correlation_length_um * 1e-6
            return RoughSurface(
                m.roughness_rms_um * 1e-6, m.correlation_length_um * 1e-6, m.psd, m.psd_exponent
            )

        kind = material.type
        if kind == "diffuse":
            values[mat.REFLECTANCE_ID] = spectra_table.add(
                np.clip(spectrum_on(material.reflectance, grid), 0, 1)
            )
            return mat.MaterialRecord(mat.MaterialKind.DIFFUSE, values), {
                "type": "diffuse",
                "reflectance": self._mitsuba_spectrum(material.reflectance, clip=True),
            }
        if kind == "mirror":
            if material.conductor == "perfect":
                values[mat.ETA_ID] = spectra_table.add_constant(0.0)
                values[mat.KAPPA_ID] = spectra_table.add_constant(1e6)  # |r| = 1 at every angle
                reference = {"type": "conductor", "material": "none"}
            else:
                conductor(material.conductor)
                reference = {"type": "conductor", "material": material.conductor}
            return mat.MaterialRecord(mat.MaterialKind.MIRROR, values), reference
        if kind == "dielectric":
            dielectric(material.ior)
            values[mat.EXTERIOR_IOR] = material.exterior_ior
            ior_value = (
                material.ior
                if isinstance(material.ior, float)
                else float(ior_data.spectral_ior(material.ior, 550.0)[0])
            )
            return mat.MaterialRecord(mat.MaterialKind.DIELECTRIC, values), {
                "type": "dielectric",
                "int_ior": ior_value,
                "ext_ior": material.exterior_ior,
            }
        placeholder = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}
        if kind == "rough_conductor":
            conductor(material.conductor)
            return mat.MaterialRecord(mat.MaterialKind.ROUGH_CONDUCTOR, values, rough(material)), placeholder
        if kind == "rough_dielectric":
            dielectric(material.ior)
            values[mat.EXTERIOR_IOR] = material.exterior_ior
            return mat.MaterialRecord(mat.MaterialKind.ROUGH_DIELECTRIC, values, rough(material)), placeholder
        if kind == "thin_film":
            values[mat.FILM_THICKNESS_M] = material.film_thickness_um * 1e-6
            values[mat.FILM_IOR_ID] = spectra_table.add(_ior_on_grid(material.film_ior, grid)[0])
            values[mat.BEAMS] = float(material.beams)
            if material.film_extinction > 0.0:
                values[mat.FILM_EXTINCTION] = material.film_extinction
            if hasattr(material.substrate, "conductor"):
                conductor(material.substrate.conductor)
            else:
                dielectric(material.substrate.ior)
                values[mat.FILM_TRANSMITS] = 1.0
            return mat.MaterialRecord(mat.MaterialKind.THIN_FILM, values, rough(material)), placeholder
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
            return mat.MaterialRecord(mat.MaterialKind.GRATING, values, grating), placeholder
        raise InputError(f"materials: type {kind!r} is not supported by the renderer")

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
    def _shape_dict(self, shape: Any) -> dict[str, Any]:
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
            return self._inline_mesh(shape)
        if kind == "mesh_file":
            if self.bundle_dir is None:
                raise InputError(f"shapes: mesh file {shape.path!r} needs an uploaded bundle")
            path = (self.bundle_dir / shape.path).resolve()
            if self.bundle_dir.resolve() not in path.parents:
                raise InputError(f"shapes: mesh file {shape.path!r} escapes the bundle")
            return {
                "type": path.suffix.lstrip(".").lower(),
                "filename": str(path),
                "to_world": _compose(mi, shape.transform, None),
            }
        raise InputError(f"shapes: type {kind!r} is not supported by the renderer")

    def _inline_mesh(self, shape: Any) -> Any:
        """An ``mi.Mesh`` of an inline or procedural mesh, the shape's transform applied to its vertices.

        Procedural meshes carry texture coordinates: Mitsuba's first shading tangent follows ∂p/∂u, which
        is what orients anisotropic materials (an optical disc's concentric grating tracks).
        """
        mi = self.mi
        if shape.type == "mesh":
            vertices = np.asarray(shape.vertices_m, dtype=np.float64)
            faces = np.asarray(shape.indices, dtype=np.uint32)
            normals = None if shape.normals is None else np.asarray(shape.normals, dtype=np.float64)
            uvs = None
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

    def _emitter(self, emitter: Any, film: model.Film) -> tuple[dict[str, Any], EmitterRecord, float]:
        """Mitsuba shape dict (without the emitter), the coherence record and the emitting area (m²)."""
        kind = emitter.type
        if kind == "sphere":
            record = EmitterRecord(EmitterKind.SPHERE, tuple(emitter.center_m), radius_m=emitter.radius_m)
            shape = {"type": "sphere", "center": list(emitter.center_m), "radius": emitter.radius_m}
            return shape, record, 4 * math.pi * emitter.radius_m**2
        if kind == "cylinder":
            p0, p1 = np.asarray(emitter.p0_m), np.asarray(emitter.p1_m)
            length = float(np.linalg.norm(p1 - p0))
            record = EmitterRecord(
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
            record = EmitterRecord(
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
            record = EmitterRecord(
                EmitterKind.DISK,
                tuple(emitter.center_m),
                axis=tuple(normal.tolist()),
                radius_m=emitter.radius_m,
            )
            own = _frame_matrix(emitter.center_m, emitter.normal, None, emitter.radius_m, emitter.radius_m)
            shape = {"type": "disk", "to_world": self.mi.ScalarTransform4f(own)}
            return shape, record, math.pi * emitter.radius_m**2
        raise InputError(f"emitters: type {kind!r} is not supported by the renderer")

    def _radiance(self, emitter: Any, area_m2: float, film: model.Film) -> dict[str, Any]:
        wavelengths = np.arange(200.0, 2500.0 + EMITTER_SPECTRUM_STEP_NM, EMITTER_SPECTRUM_STEP_NM)
        values = spectrum_on(emitter.spectrum, wavelengths)
        if emitter.power_w is not None:
            inside = (wavelengths >= film.wavelength_min_nm) & (wavelengths <= film.wavelength_max_nm)
            integral = float(np.trapezoid(values[inside], wavelengths[inside]))
            if integral <= 0:
                raise InputError("emitters: spectrum integrates to zero over the film's wavelength range")
            scale = emitter.power_w / (math.pi * area_m2 * integral)
        else:
            scale = emitter.radiance_scale
        return {
            "type": "regular",
            "wavelength_min": float(wavelengths[0]),
            "wavelength_max": float(wavelengths[-1]),
            "values": ",".join(f"{v * scale:.9g}" for v in values),
        }

    # ------------------------------------------------------------------ whole scene
    def compile(self, scene: model.Scene) -> CompiledScene:
        mi = self.mi
        film = scene.film
        camera = scene.camera
        if camera.to_world is not None:
            camera_to_world = mi.ScalarTransform4f(camera.to_world)
        else:
            camera_to_world = mi.ScalarTransform4f().look_at(
                origin=camera.origin_m, target=camera.target_m, up=camera.up
            )
        sensor = {
            "type": "perspective",
            "fov": camera.horizontal_fov_deg(),
            "fov_axis": "x",
            "near_clip": camera.near_clip_m,
            "far_clip": camera.far_clip_m,
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
        black_index = material_table.add(mat.MaterialRecord(mat.MaterialKind.BLACK))

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
            shape_dict = self._shape_dict(shape)
            shape_materials[key] = material_index[shape.material]
            if isinstance(shape_dict, dict):
                hg_dict[key] = {**shape_dict, "bsdf": {"type": "diffuse"}}
                reference_dict[key] = {**shape_dict, "bsdf": references[shape.material]}
            else:  # an inline mi.Mesh instance; its id names it like the dictionary shapes
                shape_dict.set_id(key)
                hg_dict[key] = shape_dict
                reference_dict[key] = self._inline_mesh_with_bsdf(shape, references[shape.material], key)
        emitter_table = EmitterTable()
        emitter_records: dict[str, int] = {}
        black = {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.0}}
        for index, emitter in enumerate(scene.emitters):
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
            lens,
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

    def _inline_mesh_with_bsdf(self, shape: Any, bsdf: dict, key: str) -> Any:
        mesh = self._inline_mesh(shape)
        mesh.set_id(key)
        mesh.set_bsdf(self.mi.load_dict(bsdf))
        return mesh
