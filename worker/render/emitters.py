"""Emitter geometry table and the coherence an emitter gives a receiver.

Following the BRIEF, the coherence an emitter gives a receiver is that of the *whole* emitter seen from the
receiver in the far field, with the phase taken along the direction from the emitter's centre: the
transverse covariance Σ⊥ (m²) of its projected silhouette (``hgcore.optics.sources``) in a frame ⟂ to the
centre→receiver direction, and the propagation distance r = |receiver − centre| (m). Points sampled on
the emitter by next-event estimation serve the radiometric terms only; using them for coherence too
would count decoherence twice (once through Σ⊥, once through the spread of sampled directions).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from hgcore.optics import sources


class EmitterKind(IntEnum):
    SPHERE = 0  # also a ``sun``: a sphere far away (scene_compiler.SUN_DISTANCE_M)
    CYLINDER = 1
    RECTANGLE = 2
    DISK = 3
    #: light from infinitely far in every direction (Mitsuba's ``constant`` or ``envmap``): each path
    #: carries one direction of it, a plane wave (Σ⊥ = 0; van Cittert–Zernike over the paths' directions)
    ENVIRONMENT = 4


#: The renderer's stand-in for infinity (m): a ``sun`` is a sphere this far away (``scene_compiler``), and
#: light from the environment is counted as coming from this distance in the diagnostics' r.
FAR_DISTANCE_M = 1e6

# Record layout of one emitter in the flat table (float32).
KIND, CENTER, AXIS, UP, RADIUS, LENGTH, WIDTH, HEIGHT = 0, 1, 4, 7, 10, 11, 12, 13
STRIDE = 14


@dataclass
class EmitterGeometry:
    """Geometry of one emitter in world space (metres). ``axis`` is the cylinder axis or the disk/rectangle
    normal; ``up`` the rectangle's height direction."""

    kind: EmitterKind
    center_m: tuple[float, float, float]
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    radius_m: float = 0.0
    length_m: float = 0.0
    width_m: float = 0.0
    height_m: float = 0.0

    def as_row(self) -> list[float]:
        return [
            float(self.kind),
            *self.center_m,
            *self.axis,
            *self.up,
            self.radius_m,
            self.length_m,
            self.width_m,
            self.height_m,
        ]


@dataclass
class EmitterTable:
    """Emitter records indexed by the emitters' position in the Mitsuba scene."""

    records: list[EmitterGeometry] = field(default_factory=list)

    def flat(self) -> np.ndarray:
        rows = [record.as_row() for record in self.records] or [[0.0] * STRIDE]
        return np.asarray(rows, dtype=np.float32).ravel()

    @property
    def kinds(self) -> set[EmitterKind]:
        return {record.kind for record in self.records}


def emitter_direction(mi: Any, table: Any, emitter_index: Any, receiver: Any) -> tuple[Any, Any]:
    """(distance_m, direction): centre-to-receiver distance r (m) and unit direction centre → receiver."""
    import drjit as dr

    base = emitter_index * STRIDE
    center = mi.Vector3f(*(dr.gather(mi.Float, table, base + CENTER + i) for i in range(3)))
    offset = receiver - center
    distance = dr.norm(offset)
    direction = dr.select(distance > 0, offset / dr.maximum(distance, 1e-12), mi.Vector3f(0, 0, 1))
    return distance, direction


def emitter_is_environment(mi: Any, table: Any, emitter_index: Any) -> Any:
    """Whether the emitter is the environment (light from infinity in every direction)."""
    import drjit as dr

    kind = mi.UInt32(dr.gather(mi.Float, table, emitter_index * STRIDE + KIND))
    return kind == int(EmitterKind.ENVIRONMENT)


def emitter_is_rect(mi: Any, table: Any, emitter_index: Any) -> Any:
    """Whether the emitter's angular coherence expands like a uniform rectangle (rectangles, cylinders)."""
    import drjit as dr

    kind = mi.UInt32(dr.gather(mi.Float, table, emitter_index * STRIDE + KIND))
    return (kind == int(EmitterKind.RECTANGLE)) | (kind == int(EmitterKind.CYLINDER))


@dataclass(frozen=True)
class CylinderModes:
    """The open cylinder's HG coefficients in the kernels: they depend on the view (``hgcore.optics.sources``,
    "Oblique open cylinders"), through the one parameter α = atan2(R cosθ, L sinθ) of the whitened region.

    ``values``: ``sources.open_cylinder_coefficient_table`` flattened as [node][label][mode] (float32), one
    table for every cylinder of the scene; ``modes`` its (n, m); ``rect_coefficients`` the uniform
    rectangle's, for the other emitters that expand like rectangles. Per lane the coefficients are
    interpolated linearly in α between the two nearest nodes (|Δĉ_nm| ≤ OPEN_CYLINDER_TABLE_MAX_ABS_ERROR
    = 9.3e-4, Σ|Δĉ| ≤ 3.1e-3, hence |Δμ| ≤ 1.8e-3: measured by ``bench/bench_cylinder_modes.py``), in the
    label of Σ's major axis (û where Σ_uu ≥ Σ_vv, else v; ``degree_of_coherence`` orders its whitened axes
    the same way). Built only for scenes with a cylinder and more than one mode (one mode: ĉ₀₀ = √π for all).
    """

    values: Any
    modes: tuple[tuple[int, int], ...]
    samples: int
    rect_coefficients: dict[tuple[int, int], float]

    @classmethod
    def for_scene(cls, mi: Any, kinds: set[EmitterKind], mode_count: int) -> CylinderModes | None:
        if EmitterKind.CYLINDER not in kinds or mode_count == 1:
            return None
        modes, table = sources.open_cylinder_coefficient_table(mode_count)
        values = mi.Float(np.ascontiguousarray(table, dtype=np.float32).ravel())
        return cls(values, modes, table.shape[0], sources.source_coefficients("rect", mode_count))

    def coefficients(
        self, mi: Any, table: Any, emitter_index: Any, frame_x: Any, frame_y: Any
    ) -> dict[tuple[int, int], Any]:
        """ĉ_nm per lane for emitter ``emitter_index`` seen along the direction ⟂ to the frame (the frame of
        its Σ⊥ in ``emitter_coherence``): the cylinder's by its obliquity, the rectangle's for other kinds."""
        import drjit as dr

        from worker.render.drjit_ops import drjit_ops

        base = emitter_index * STRIDE

        def read(offset: int):
            return dr.gather(mi.Float, table, base + offset)

        radius, length = read(RADIUS), read(LENGTH)
        axis = mi.Vector3f(read(AXIS), read(AXIS + 1), read(AXIS + 2))
        axis_x, axis_y = dr.dot(axis, frame_x), dr.dot(axis, frame_y)
        sin_theta2 = axis_x * axis_x + axis_y * axis_y
        sin_theta = dr.sqrt(dr.minimum(sin_theta2, 1.0))
        cos_theta = dr.sqrt(dr.maximum(1.0 - sin_theta2, 0.0))
        sigma_uu, sigma_vv = sources.cylinder_silhouette_moments(radius, length, sin_theta, cos_theta)
        cylinder = mi.UInt32(read(KIND)) == int(EmitterKind.CYLINDER)
        alpha = sources.open_cylinder_obliquity(radius, length, sin_theta, cos_theta, drjit_ops())
        # Other kinds store R = L = 0 (atan2(0, 0)): any node would do, but keep the index finite.
        alpha = dr.select(cylinder & dr.isfinite(alpha), alpha, 0.0)
        position = alpha * ((self.samples - 1) / (0.5 * dr.pi))
        node = mi.UInt32(dr.clip(dr.floor(position), 0.0, self.samples - 2.0))
        weight = position - mi.Float(node)
        label = dr.select(sigma_uu >= sigma_vv, mi.UInt32(0), mi.UInt32(1))
        width = len(self.modes)
        low_row = (node * 2 + label) * width
        high_row = low_row + 2 * width
        result = {}
        for column, mode in enumerate(self.modes):
            low = dr.gather(mi.Float, self.values, low_row + column)
            high = dr.gather(mi.Float, self.values, high_row + column)
            result[mode] = dr.select(cylinder, dr.fma(weight, high - low, low), self.rect_coefficients[mode])
        return result


def emitter_rect_modes(
    mi: Any, table: Any, cylinder_modes: CylinderModes | None, emitter_index: Any, frame_x: Any, frame_y: Any
) -> dict[tuple[int, int], Any] | None:
    """Per-lane ĉ of the emitters that expand like rectangles (``CylinderModes.coefficients``), or None —
    the universal rectangle's — where the scene has no cylinder table (nothing is traced then)."""
    if cylinder_modes is None:
        return None
    return cylinder_modes.coefficients(mi, table, emitter_index, frame_x, frame_y)


def sphere_solid_angle(mi: Any, table: Any, emitter_index: Any, distance_m: Any) -> tuple[Any, Any]:
    """(whether the emitter is a sphere seen from outside, the solid angle Ω (sr) it subtends from a
    receiver ``distance_m`` from its centre).

    Ω = 2π(1 − cos α), sin α = a/d, formed as 2π sin²α/(1 + cos α): float32 1 − cos α cancels, so Mitsuba's
    cone pdf 1/Ω is 3 % high at a/d = 1.7e-3 (a 1 mm sphere at 0.6 m) and infinite below a/d ≈ 2.4e-4
    (cos α rounds to 1: emitter weight 0, MIS weight ∞/∞ = NaN).
    """
    import drjit as dr

    base = emitter_index * STRIDE
    kind = mi.UInt32(dr.gather(mi.Float, table, base + KIND))
    radius = dr.gather(mi.Float, table, base + RADIUS)
    sin_sq = dr.square(radius / dr.maximum(distance_m, 1e-30))
    outside = (kind == int(EmitterKind.SPHERE)) & (sin_sq < 1.0)
    cos_alpha = dr.sqrt(dr.maximum(1.0 - sin_sq, 0.0))
    return outside, 2.0 * dr.pi * sin_sq / (1.0 + cos_alpha)


def emitter_coherence(
    mi: Any,
    table: Any,
    kinds: set[EmitterKind],
    emitter_index: Any,
    frame_x: Any,
    frame_y: Any,
) -> tuple[Any, Any, Any]:
    """Σ⊥ (m²) of emitter ``emitter_index`` (UInt32 per lane) seen along the direction ⟂ to the frame.

    Returns ``(sigma_xx, sigma_xy, sigma_yy)`` in the frame spanned by ``frame_x``/``frame_y``, which the
    caller makes ⟂ to the centre → receiver direction: the projected silhouettes depend on that frame
    only. Only branches for emitter ``kinds`` present in the scene are compiled
    into the kernel.
    """
    import drjit as dr

    from worker.render.drjit_ops import drjit_ops

    ops = drjit_ops()
    base = emitter_index * STRIDE

    def read(offset: int):
        return dr.gather(mi.Float, table, base + offset)

    def read3(offset: int):
        return mi.Vector3f(read(offset), read(offset + 1), read(offset + 2))

    kind = mi.UInt32(read(KIND))
    radius = read(RADIUS)
    sigma = (mi.Float(0.0), mi.Float(0.0), mi.Float(0.0))

    def choose(mask, candidate):
        return tuple(dr.select(mask, c, s) for c, s in zip(candidate, sigma, strict=True))

    fx, fy = (frame_x.x, frame_x.y, frame_x.z), (frame_y.x, frame_y.y, frame_y.z)

    def vec(v):
        return (v.x, v.y, v.z)

    if EmitterKind.SPHERE in kinds:
        sigma = choose(kind == int(EmitterKind.SPHERE), sources.sphere_covariance_components(radius))
    if EmitterKind.CYLINDER in kinds:
        candidate = sources.cylinder_covariance_components(
            radius, read(LENGTH), vec(read3(AXIS)), fx, fy, ops
        )
        sigma = choose(kind == int(EmitterKind.CYLINDER), candidate)
    if EmitterKind.RECTANGLE in kinds:
        up = read3(UP)
        width_axis = dr.cross(up, read3(AXIS))
        candidate = sources.rectangle_covariance_components(
            read(WIDTH), read(HEIGHT), vec(width_axis), vec(up), fx, fy
        )
        sigma = choose(kind == int(EmitterKind.RECTANGLE), candidate)
    if EmitterKind.DISK in kinds:
        sigma = choose(
            kind == int(EmitterKind.DISK),
            sources.disk_covariance_components(radius, vec(read3(AXIS)), fx, fy),
        )
    return sigma
