"""Oblique cylinder lights: the kernels' view-dependent HG modes (``emitters.CylinderModes``).

The exact even modes of an open cylinder's radiating region (``sources.open_cylinder_coefficients``, checked
against a ray-cast van Cittert–Zernike in tests/optics/test_cylinder_modes.py) depend on the view through
α = atan2(R cosθ, L sinθ); the kernels interpolate them from a table over α whose error is bounded by
``sources.OPEN_CYLINDER_TABLE_MAX_ABS_ERROR`` (measured at every table midpoint by
bench/bench_cylinder_modes.py). Float32 adds ≤ 1e-6 (coefficients ≤ 2, table values and lerp weights
rounded at 6e-8 relative, α to 1e-7 rad with |dĉ/dα| ≲ 1).

Through the film kernels: a coated silver mirror at 45° reflects towards the camera the direction of an
oblique cylinder's centre (R 2 cm, L 8 cm, 10 cm away, axis at 30° to the line of sight, in the plane of
incidence so that the film shear lies along the projected axis û). Where the whole tube reaches the film —
the film seen through a non-specular vertex (``IncidentCoherence.acceptance_unbounded``), the paper's
Eq. 18 — the film's response is R(V) with the two-beam reflectance (Eq. 18) and V = μ(s⊥) of the cylinder
at the film shear s⊥ = 2τ tan θ_f cos θ_i along û (whitened |u| ≈ 2 at 525 nm, where the exact and
rectangle modes differ most). Evaluated as the integrator does (``HGPathIntegrator._emitter_light``: the
tube's Σ⊥ and view-dependent modes at the film point; ``bsdfs.thin_film``: the detected light, the film's
terms and shear at the tube's centre direction, the visibilities), without Monte Carlo: at 9 wavelengths
over 505–545 nm against the exact modes' prediction, within the table's |Δμ| ≤ 1.8e-3 (≤ 2·|X₁|·1.8e-3 of R)
plus float32 rounding; the rectangle's modes are ≈ 2.5 % away. (A smooth film seen straight from a camera
passes one direction of the tube — V = 1, docs/physics_interactions.md §3 — so a render of that view no
longer shows the modes; this evaluation isolates them.)
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest

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
from worker.render.bsdfs.thin_film import detected_light, film_at_directions, visible_reflectance
from worker.render.chunks import renderer_for
from worker.render.emitters import (
    CylinderModes,
    EmitterGeometry,
    EmitterKind,
    EmitterTable,
    emitter_direction,
)
from worker.render.materials import MaterialKind

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


def expected_reflectance(
    wavelengths_nm: np.ndarray, coefficients: dict[tuple[int, int], float]
) -> np.ndarray:
    """R(V) at ``wavelengths_nm``, V = μ(s⊥) of the tube in its (û, v) frame with ``coefficients``."""
    sin_tilt, cos_tilt = math.sin(math.radians(TILT_DEG)), math.cos(math.radians(TILT_DEG))
    sigma_uu, sigma_vv = cylinder_silhouette_moments(RADIUS_M, LENGTH_M, sin_tilt, cos_tilt)
    incidence = math.radians(INCIDENCE_DEG)
    shear_m = 2.0 * THICKNESS_M * math.tan(math.asin(math.sin(incidence) / FILM_IOR)) * math.cos(incidence)
    wavelengths_m = np.asarray(wavelengths_nm, dtype=float) * 1e-9
    substrate = ComplexPair(*ior.spectral_ior("Ag", wavelengths_m * 1e9))
    cos_i = np.full_like(wavelengths_m, math.cos(incidence))
    terms = film_reflectance_terms(cos_i, wavelengths_m, THICKNESS_M, FILM_IOR, substrate, 1.0, BEAMS, NUMPY)
    along = np.full_like(wavelengths_m, shear_m)
    visibility = degree_of_coherence(
        (along, 0.0 * along), (sigma_uu, 0.0, sigma_vv), DISTANCE_M, wavelengths_m, coefficients
    )
    return bounded_reflectance(terms, [visibility], NUMPY), np.abs(terms[1])


def kernel_reflectance(wavelengths_nm: np.ndarray) -> np.ndarray:
    """The film's R(V) at the mirror's centre as the integrator evaluates it for light from the whole tube
    (one lane per wavelength, all four of its wavelengths equal)."""
    renderer = renderer_for(validate_scene(coated_mirror_scene()))
    mi, integrator = renderer.mi, renderer.integrator
    kernels, context = integrator.kernels, integrator.context
    lanes = len(wavelengths_nm)
    wavelengths = mi.Spectrum(mi.Float(np.asarray(wavelengths_nm, dtype=np.float32)))
    receiver = mi.Point3f(*(mi.Float(np.zeros(lanes, dtype=np.float32)) for _ in range(3)))
    record = mi.UInt32(np.zeros(lanes, dtype=np.uint32))
    coherence, _ = integrator._emitter_light(mi.Bool(True), record, receiver, None)
    coherence.acceptance_unbounded = mi.Bool(True)
    _, from_centre = emitter_direction(mi, context.emitter_flat, record, receiver)
    up = mi.Vector3f(0.0, 0.0, 1.0)
    normal = (dr.dot(up, coherence.frame_x), dr.dot(up, coherence.frame_y), dr.dot(up, from_centre))
    inverse_r2 = dr.rcp(dr.square(coherence.distance_m))
    source = (
        coherence.sigma_xx * inverse_r2,
        coherence.sigma_xy * inverse_r2,
        coherence.sigma_yy * inverse_r2,
    )
    zero = mi.Float(np.zeros(lanes, dtype=np.float32))
    light = detected_light(
        normal,
        (zero, zero),
        source,
        (zero, zero),
        mi.Spectrum(0.0),
        True,
        coherence.rect_source,
        wavelengths,
    )
    (film,) = renderer.compiled.material_table.indices_of(MaterialKind.THIN_FILM)
    spectra = kernels.vertex_spectra(mi.UInt32(np.full(lanes, film, dtype=np.uint32)), wavelengths)
    terms, shears = film_at_directions(spectra, normal, light.means)
    reflectance = visible_reflectance(
        terms, shears, light.covariances, coherence, kernels.visibility, wavelengths
    )
    return np.asarray(reflectance[0], dtype=float)


WAVELENGTHS_NM = np.linspace(505.0, 545.0, 9)


def test_oblique_cylinder_fringes_use_its_exact_modes_where_the_whole_tube_reaches_the_film() -> None:
    values = kernel_reflectance(WAVELENGTHS_NM)
    exact, interference = expected_reflectance(
        WAVELENGTHS_NM,
        open_cylinder_coefficients(RADIUS_M, LENGTH_M, math.sin(math.radians(TILT_DEG)), MODES),
    )
    rectangle, _ = expected_reflectance(WAVELENGTHS_NM, source_coefficients("rect", MODES))
    tolerance = 2.0 * interference * 1.8e-3 + 1e-5
    assert np.all(np.abs(values - exact) <= tolerance), (values, exact, rectangle)
    # the rectangle modes (used for cylinders before their own) are rejected at most wavelengths
    assert np.sum(np.abs(values - rectangle) > tolerance) >= 6, (values, exact, rectangle)


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
