"""Oblique cylinder lights: the kernels' view-dependent HG modes (``emitters.CylinderModes``).

The exact even modes of an open cylinder's radiating region (``sources.open_cylinder_coefficients``, checked
against a ray-cast van Cittert–Zernike in tests/optics/test_cylinder_modes.py) depend on the view through
α = atan2(R cosθ, L sinθ); the kernels interpolate them from a table over α whose error is bounded by
``sources.OPEN_CYLINDER_TABLE_MAX_ABS_ERROR`` (measured at every table midpoint by
bench/bench_cylinder_modes.py). Float32 adds ≤ 1e-6 (coefficients ≤ 2, table values and lerp weights
rounded at 6e-8 relative, α to 1e-7 rad with |dĉ/dα| ≲ 1).

End to end: a camera looks at a coated silver mirror at 45°; the mirror reflects it straight into an oblique
cylinder (R 2 cm, L 8 cm, 10 cm away, axis at 30° to the line of sight, in the plane of incidence so that the
film shear lies along the projected axis û). Every camera path hits the tube's lateral surface (the ray to
its centre enters it R cot θ = 1.7R < L/2 from the centre), so the pixel is L_e·R(V) with R the two-beam
film reflectance (Eq. 18) and V = μ(s⊥) of the cylinder at the film shear s⊥ = 2τ tan θ_f cos θ_i along û
(whitened |u| ≈ 2 at 525 nm, where the exact and rectangle modes differ most). 4 bands over 505–545 nm: the
four hero lanes fall one in each band, so a band carries no sample-count noise, only the spread of R(λ)
within 10 nm; 16 pixels × 64 spp give a standard error ≈ 0.05 %. The pixel footprint (fov 0.01°: ±0.1 mm
on the mirror, ±0.07° of incidence) moves the film phase by ≤ 0.02 rad. Tolerance: 5 SE from the pixels'
scatter plus 0.5 % (footprint, and |Δμ| ≤ 1.8e-3 of the table, ≤ 0.1 % of R here), against a difference of
≈ 2.5 % between the two predictions.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.optics import ior
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.coherence import degree_of_coherence
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.frames import transverse_frame
from hgcore.optics.sources import (
    OPEN_CYLINDER_TABLE_MAX_ABS_ERROR,
    cylinder_silhouette_moments,
    open_cylinder_coefficients,
    source_coefficients,
)
from hgcore.optics.thin_film import bounded_reflectance, film_reflectance_terms
from schemas import build, validate_scene
from tests.integrator.scenes import coated_plane
from worker.mitsuba_setup import configured_mitsuba
from worker.render.chunks import render_scene
from worker.render.emitters import CylinderModes, EmitterGeometry, EmitterKind, EmitterTable

MODES = 16
FLOAT32_ERROR = 1e-6
TOLERANCE = OPEN_CYLINDER_TABLE_MAX_ABS_ERROR + FLOAT32_ERROR
VIEW_ANGLES_DEG = [5.0, 10.0, 20.0, 30.0, 45.0, 60.0, 75.0, 89.0, 90.0]
# A short tube (Σ's major axis across it at every angle) and a long one (along it until near end-on), with
# the angles at which the rectangle's modes are off by more than 10 tolerances.
CYLINDERS = [((0.01, 0.02), [5.0, 10.0, 20.0, 30.0, 45.0, 60.0]), ((0.02, 0.15), [5.0, 10.0, 20.0, 30.0])]


def _unit(vector) -> np.ndarray:
    array = np.asarray(vector, dtype=float)
    return array / np.linalg.norm(array)


def kernel_coefficients(radius_m: float, length_m: float, angles_deg: list[float]) -> list[dict]:
    """``CylinderModes.coefficients`` for one cylinder seen at each angle θ (view direction to axis), one
    lane per angle, in a transverse frame turned about the view (the kernel may not assume û = x)."""
    mi = configured_mitsuba()
    axis = _unit((0.3, -0.5, 0.8))
    record = EmitterGeometry(
        EmitterKind.CYLINDER, (0.1, 0.2, 0.3), axis=tuple(axis), radius_m=radius_m, length_m=length_m
    )
    across = _unit(np.cross(axis, (1.0, 0.0, 0.0)))
    frames = []
    for angle in angles_deg:
        theta = math.radians(angle)
        direction = math.cos(theta) * axis + math.sin(theta) * across
        frames.append(transverse_frame(direction, tuple(axis + across + (0.0, 0.0, 0.3))))

    def vectors(rows: list[np.ndarray]):
        return mi.Vector3f(*(mi.Float(np.array(rows)[:, i].astype(np.float32)) for i in range(3)))

    modes = CylinderModes.for_scene(mi, {EmitterKind.CYLINDER}, MODES)
    lanes = mi.UInt32(np.zeros(len(angles_deg), dtype=np.uint32))
    table = mi.Float(EmitterTable([record]).flat())
    x_axes, y_axes = vectors([x for x, _ in frames]), vectors([y for _, y in frames])
    values = modes.coefficients(mi, table, lanes, x_axes, y_axes)
    arrays = {mode: np.asarray(value, dtype=float) for mode, value in values.items()}
    return [{mode: float(array[lane]) for mode, array in arrays.items()} for lane in range(len(angles_deg))]


@pytest.mark.parametrize(("size_m", "discriminating_deg"), CYLINDERS)
def test_kernel_modes_are_the_exact_modes_at_every_view_angle(
    size_m: tuple[float, float], discriminating_deg: list[float]
) -> None:
    radius_m, length_m = size_m
    rectangle = source_coefficients("rect", MODES)
    for angle, kernel in zip(
        VIEW_ANGLES_DEG, kernel_coefficients(radius_m, length_m, VIEW_ANGLES_DEG), strict=True
    ):
        exact = open_cylinder_coefficients(radius_m, length_m, math.sin(math.radians(angle)), MODES)
        # the kernel drops the modes with an odd index, zero by the region's symmetry
        assert max(abs(value) for mode, value in exact.items() if mode not in kernel) < 1e-12
        error = max(abs(kernel[mode] - exact[mode]) for mode in kernel)
        assert error <= TOLERANCE, (angle, error)
        rectangle_error = max(abs(rectangle[mode] - exact[mode]) for mode in kernel)
        if angle in discriminating_deg:
            assert rectangle_error > 10.0 * TOLERANCE, (angle, rectangle_error)


def test_side_on_cylinders_keep_the_rectangle_modes() -> None:
    """Side-on the radiating region is the uniform strip L × 2R: the rectangle kind's modes, as before."""
    rectangle = source_coefficients("rect", MODES)
    for (radius_m, length_m), _ in CYLINDERS:
        (kernel,) = kernel_coefficients(radius_m, length_m, [90.0])
        assert max(abs(kernel[mode] - rectangle[mode]) for mode in kernel) <= FLOAT32_ERROR


# ------------------------------------------------------------------------------------------ end to end
RADIUS_M, LENGTH_M, TILT_DEG, DISTANCE_M = 0.02, 0.08, 30.0, 0.1
THICKNESS_M, FILM_IOR, BEAMS, INCIDENCE_DEG = 1.9e-6, 1.5, 2, 45.0
EDGES_NM = np.linspace(505.0, 545.0, 5)


def coated_mirror_scene() -> dict:
    incidence = math.radians(INCIDENCE_DEG)
    view = np.array([math.sin(incidence), 0.0, math.cos(incidence)])
    towards_light = np.array([-view[0], 0.0, view[2]])
    across_beam = np.array([view[2], 0.0, view[0]])  # ⟂ to the reflected beam, in the plane of incidence
    tilt = math.radians(TILT_DEG)
    axis = math.cos(tilt) * towards_light + math.sin(tilt) * across_beam
    centre = DISTANCE_M * towards_light
    return coated_plane(
        "oblique cylinder over a coated mirror",
        view=view,
        film=build.film(
            4,
            bands=4,
            spp=64,
            max_depth=3,
            modes=MODES,
            wavelength_min_nm=float(EDGES_NM[0]),
            wavelength_max_nm=float(EDGES_NM[-1]),
        ),
        coating={
            "film_thickness_um": THICKNESS_M * 1e6,
            "film_ior": FILM_IOR,
            "substrate": {"conductor": "Ag"},
            "beams": BEAMS,
        },
        emitter={
            "type": "cylinder",
            "p0_m": (centre - 0.5 * LENGTH_M * axis).tolist(),
            "p1_m": (centre + 0.5 * LENGTH_M * axis).tolist(),
            "radius_m": RADIUS_M,
            "spectrum": {"type": "constant", "value": 1.0},
            "radiance_scale": 1.0,
        },
        fov_deg=0.01,
    )


def expected_band_values(coefficients: dict[tuple[int, int], float]) -> np.ndarray:
    """Band averages (Simpson, ≤ 2 nm steps) of L_e·R(V), V = μ(s⊥) in the cylinder's (û, v) frame."""
    sin_tilt, cos_tilt = math.sin(math.radians(TILT_DEG)), math.cos(math.radians(TILT_DEG))
    sigma_uu, sigma_vv = cylinder_silhouette_moments(RADIUS_M, LENGTH_M, sin_tilt, cos_tilt)
    incidence = math.radians(INCIDENCE_DEG)
    shear_m = 2.0 * THICKNESS_M * math.tan(math.asin(math.sin(incidence) / FILM_IOR)) * math.cos(incidence)
    values = []
    for low, high in itertools.pairwise(EDGES_NM):
        intervals = 2 * math.ceil((high - low) / 4.0)
        wavelengths_m = np.linspace(low, high, intervals + 1) * 1e-9
        substrate = ComplexPair(*ior.spectral_ior("Ag", wavelengths_m * 1e9))
        cos_i = np.full_like(wavelengths_m, math.cos(incidence))
        terms = film_reflectance_terms(
            cos_i, wavelengths_m, THICKNESS_M, FILM_IOR, substrate, 1.0, BEAMS, NUMPY
        )
        along = np.full_like(wavelengths_m, shear_m)
        visibility = degree_of_coherence(
            (along, 0.0 * along), (sigma_uu, 0.0, sigma_vv), DISTANCE_M, wavelengths_m, coefficients
        )
        reflectance = bounded_reflectance(terms, [visibility], NUMPY)
        simpson = np.ones_like(reflectance)
        simpson[1:-1:2], simpson[2:-1:2] = 4.0, 2.0
        values.append(np.sum(simpson * reflectance) / np.sum(simpson))
    return np.array(values)


def exact_and_rectangle_predictions() -> tuple[np.ndarray, np.ndarray]:
    sin_tilt = math.sin(math.radians(TILT_DEG))
    exact = expected_band_values(open_cylinder_coefficients(RADIUS_M, LENGTH_M, sin_tilt, MODES))
    return exact, expected_band_values(source_coefficients("rect", MODES))


def test_oblique_cylinder_renders_the_fringes_of_its_exact_modes(tmp_path: Path) -> None:
    render_scene(validate_scene(coated_mirror_scene()), tmp_path, seed=5)
    image = read_exr(tmp_path / "image.exr")
    bands = [name for name in image.channels if name.startswith("S0.")]
    per_pixel = np.stack([image.channels[name].astype(float).ravel() for name in bands])
    values = per_pixel.mean(axis=1)
    error = per_pixel.std(axis=1, ddof=1) / math.sqrt(per_pixel.shape[1])
    exact, rectangle = exact_and_rectangle_predictions()
    tolerance = 5.0 * error + 0.005 * exact
    assert np.all(np.abs(values - exact) <= tolerance), (values, exact, rectangle, error)
    # the rectangle modes (used for cylinders until now) are rejected in most bands
    assert np.sum(np.abs(values - rectangle) > tolerance) >= 3, (values, exact, rectangle, error)


def test_exact_and_rectangle_modes_predict_different_fringes() -> None:
    """The two predictions differ by far more than the end-to-end tolerance (that test can fail)."""
    exact, rectangle = exact_and_rectangle_predictions()
    assert np.sum(np.abs(exact - rectangle) > 0.01 * exact) >= 3, (exact, rectangle)  # 2.4–2.6 % in 3 bands


def test_rectangles_beside_a_cylinder_keep_the_rectangle_modes() -> None:
    """In a scene with both, the per-lane coefficients of a rectangle's lanes are the universal ones."""
    mi = configured_mitsuba()
    records = [
        EmitterGeometry(
            EmitterKind.CYLINDER, (0.0, 0.0, 0.0), axis=(0.0, 0.6, 0.8), radius_m=0.01, length_m=0.02
        ),
        EmitterGeometry(EmitterKind.RECTANGLE, (0.0, 0.0, 1.0), width_m=0.3, height_m=0.1),
    ]
    modes = CylinderModes.for_scene(mi, {EmitterKind.CYLINDER, EmitterKind.RECTANGLE}, MODES)
    lanes = mi.UInt32([0, 1])
    frame_x, frame_y = (
        mi.Vector3f([1.0, 1.0], [0.0, 0.0], [0.0, 0.0]),
        mi.Vector3f([0.0, 0.0], [1.0, 1.0], 0.0),
    )
    values = modes.coefficients(mi, mi.Float(EmitterTable(records).flat()), lanes, frame_x, frame_y)
    rectangle = source_coefficients("rect", MODES)
    assert all(
        abs(float(np.asarray(value)[1]) - rectangle[mode]) <= FLOAT32_ERROR for mode, value in values.items()
    )
    assert max(abs(float(np.asarray(value)[0]) - rectangle[mode]) for mode, value in values.items()) > 0.1
