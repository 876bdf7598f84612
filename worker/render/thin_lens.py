"""The thin-lens camera (``camera.aperture_radius_m`` > 0): depth of field, and the cone of directions a
pixel collects.

A thin lens of radius a in the camera's xy plane, focused on the plane z = z_f in front of it (camera
frame: Mitsuba's, looking along +z), images the point P_f of that plane that a pixel's pinhole ray
through the lens centre c reaches, P_f = c + d·z_f/(d·ẑ), onto the pixel. So the pixel receives the rays
from every lens point u = c + a·(x·x̂ + y·ŷ), (x, y) uniform on the unit disk, towards P_f:
d' = (P_f − u)/|P_f − u|.
This is Mitsuba's ``thinlens`` sensor (``src/sensors/thinlens.cpp``: the same concentric disk map of the
aperture sample, the ray starting on the near clip plane, importance weight 1), written out here because
that sensor cannot be recorded by a frozen render pass in Mitsuba 3.9 (one of its members is not
traversable); ``hg_path`` renders with Mitsuba's ``perspective`` sensor and this lens on top, the
reference scenes with Mitsuba's own ``thinlens`` (tests/integrator/test_thin_lens.py compares them).

Every ray of a pixel meets the same point of the focal plane, so a pixel's rays spread over a cone of
angular radius ≈ a/|P_f − c| around its chief ray, whatever they hit on the way: through a smooth film
each ray reflects one direction of a source, and the pixel averages the film's fringes over the source
directions its cone reflects onto — the detector's share of the coherence a pixel observes
(docs/physics_interactions.md §3, "What a pixel sees"). The renderer samples the lens like any other
camera dimension, so that average is taken by the paths themselves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ThinLens:
    """A thin lens: radius ``aperture_radius_m`` (> 0), focus distance ``focus_distance_m`` along the view
    axis, the camera's near/far clip distances (m) and its world-space centre and axes (Mitsuba's camera
    frame: ``axis_x`` towards the image's left, ``axis_y`` up, ``axis_z`` forward)."""

    aperture_radius_m: float
    focus_distance_m: float
    near_clip_m: float
    far_clip_m: float
    centre: tuple[float, float, float]
    axis_x: tuple[float, float, float]
    axis_y: tuple[float, float, float]
    axis_z: tuple[float, float, float]

    def on_device(self, mi: Any) -> LensArrays:
        """The lens as opaque arrays: the kernels of scenes that differ only in their lens are the same
        (LLVM compiles once, ≈ 3.5 s saved per further lens), and a frozen pass names them as inputs."""
        import drjit as dr

        scalars = [mi.Float(value) for value in (self.aperture_radius_m, self.focus_distance_m)]
        scalars += [mi.Float(value) for value in (self.near_clip_m, self.far_clip_m)]
        vectors = [mi.Vector3f(*vector) for vector in (self.centre, self.axis_x, self.axis_y, self.axis_z)]
        dr.make_opaque(*scalars, *vectors)
        return LensArrays(*scalars, *vectors)


@dataclass
class LensArrays:
    """``ThinLens`` on the device (Dr.Jit arrays of one element)."""

    aperture_radius_m: Any
    focus_distance_m: Any
    near_clip_m: Any
    far_clip_m: Any
    centre: Any
    axis_x: Any
    axis_y: Any
    axis_z: Any

    def kernel_tables(self) -> list[Any]:
        """The arrays the lens's kernels read (what a frozen pass names as inputs)."""
        return [getattr(self, name) for name in self.__dataclass_fields__]

    def ray(self, mi: Any, pinhole_ray: Any, aperture_sample: Any) -> Any:
        """The lens ray of the pixel whose pinhole ray (from Mitsuba's ``perspective`` sensor: direction d
        from the centre, origin on the near plane) is ``pinhole_ray``, through the lens point that
        ``aperture_sample`` ∈ [0, 1)² maps to (concentric disk map, as Mitsuba's ``thinlens``)."""
        import drjit as dr

        pinhole_d = pinhole_ray.d
        focus_point = self.centre + pinhole_d * (self.focus_distance_m / dr.dot(pinhole_d, self.axis_z))
        disk = mi.warp.square_to_uniform_disk_concentric(aperture_sample) * self.aperture_radius_m
        lens_point = self.centre + self.axis_x * disk.x + self.axis_y * disk.y
        direction = dr.normalize(focus_point - lens_point)
        inverse_z = dr.rcp(dr.dot(direction, self.axis_z))
        near_t, far_t = self.near_clip_m * inverse_z, self.far_clip_m * inverse_z
        return mi.Ray3f(
            mi.Point3f(lens_point + direction * near_t),
            direction,
            far_t - near_t,
            pinhole_ray.time,
            pinhole_ray.wavelengths,
        )
