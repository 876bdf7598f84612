"""Source covariances Σ⊥ (closed forms vs Monte Carlo of silhouettes), numeric paths, Eq. 14 coefficients."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import j1

from hgcore.optics.array_ops import NUMPY, hermite_functions
from hgcore.optics.coherence import shape_matrix_from_log_hessian
from hgcore.optics.frames import transverse_frame
from hgcore.optics.sources import (
    covariance_from_angular_coherence,
    covariance_from_intensity_image,
    cylinder_covariance_components,
    disk_covariance_components,
    log_hessian_at_origin,
    rectangle_covariance_components,
    source_coefficients,
    sphere_covariance_components,
    transverse_covariance,
)
from tests.optics.silhouettes import MC_SIGMAS, silhouette_samples, unit


def assert_covariance_matches_samples(expected: np.ndarray, samples: np.ndarray) -> None:
    """Each entry of the sample second-moment matrix within 5 standard errors of ``expected``."""
    centred = samples - samples.mean(axis=0)
    for i, j in [(0, 0), (0, 1), (1, 1)]:
        products = centred[:, i] * centred[:, j]
        standard_error = products.std(ddof=1) / math.sqrt(len(products))
        assert abs(products.mean() - expected[i, j]) < MC_SIGMAS * standard_error + 1e-15, (i, j)


@pytest.mark.parametrize("tilt_deg", [90.0, 75.0, 60.0, 45.0, 30.0, 15.0, 8.0, 3.0])
def test_cylinder_closed_form_matches_monte_carlo_silhouette(tilt_deg: float) -> None:
    """The open cylinder's Σ⊥ against a ray-cast of its radiating surface, 3°–90° (end-on it radiates
    nothing towards the receiver). Short and long tubes: at small tilts the near opening and the far bulge
    overlap the projected length."""
    radius, length = 0.02, 0.15
    direction = unit((0.1, -0.2, 1.0))
    x_axis, y_axis = transverse_frame(direction)
    # Axis at tilt θ from the line of sight, turned 35° about it so that Σ_xy ≠ 0 in the frame.
    tilt, turn = math.radians(tilt_deg), math.radians(35.0)
    axis = unit(
        tuple(
            math.cos(tilt) * direction + math.sin(tilt) * (math.cos(turn) * x_axis + math.sin(turn) * y_axis)
        )
    )
    for length in (0.15, 0.02):
        sxx, sxy, syy = cylinder_covariance_components(
            radius, length, tuple(axis), tuple(x_axis), tuple(y_axis)
        )
        expected = np.array([[sxx, sxy], [sxy, syy]])
        samples = silhouette_samples(radius, length, axis, direction, 400_000, seed=int(tilt_deg) + 1)
        assert len(samples) > 1_000
        assert_covariance_matches_samples(expected, samples)


def test_short_cylinder_at_30_degrees_has_the_radiating_surfaces_coherence() -> None:
    """Issue 12: R 1 cm, L 2 cm seen at 30° from 0.6 m: VCZ of the radiating surface gives 15.1/9.1 µm."""
    from hgcore.optics.calculator import coherence_at

    result = coherence_at(
        "cylinder",
        radius_m=0.01,
        length_m=0.02,
        distance_m=0.6,
        axis=(math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))),
    )
    assert result["l1_um"] == pytest.approx(15.1, abs=0.05)
    assert result["l2_um"] == pytest.approx(9.1, abs=0.05)


def test_cylinder_limits_end_on_and_side_on() -> None:
    radius, length = 0.01, 0.3
    frame = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    end_on = cylinder_covariance_components(radius, length, (0.0, 0.0, 1.0), *frame)
    np.testing.assert_allclose(end_on, (radius**2 / 3, 0.0, radius**2 / 3), rtol=1e-14, atol=0.0)
    side_on = cylinder_covariance_components(radius, length, (1.0, 0.0, 0.0), *frame)
    np.testing.assert_allclose(side_on, (length**2 / 12, 0.0, radius**2 / 3), rtol=1e-14, atol=0.0)
    # Just off end-on the formula is continuous (no division blow-up from the projected-axis direction).
    # Just off end-on the lateral surface is a thin crescent: Σ_uu → R²(2/3 − π²/16) along the axis.
    nearly = cylinder_covariance_components(radius, length, tuple(unit((1e-5, 0.0, 1.0))), *frame)
    crescent = radius**2 * (2 / 3 - math.pi**2 / 16)
    np.testing.assert_allclose(nearly, (crescent, 0.0, radius**2 / 3), rtol=1e-4, atol=1e-12)


def test_fig7_cylinder_and_sphere_numbers() -> None:
    # Paper Fig. 7: cylinder R = 0.1 cm, L = 20 cm side-on at 60 cm: ℓ along the axis = r/(k L/√12)
    # ≈ 0.91 µm ("less than a micron") and across = r/(k R/√3) ≈ 91 µm ("tens of µm"). Sphere R = 0.6 cm:
    # ℓ = r/(k R/2) ≈ 17.5 µm (paper: "about 15 µm × 15 µm"; its cut-off factor is ad hoc, Cor. 4.2).
    from hgcore.optics.calculator import coherence_at

    k = 2 * math.pi / 550e-9
    cylinder = coherence_at("cylinder", radius_m=0.001, length_m=0.2, distance_m=0.6)
    assert cylinder["l2_um"] == pytest.approx(1e6 * 0.6 / (k * 0.2 / math.sqrt(12)), rel=1e-12)
    assert cylinder["l1_um"] == pytest.approx(1e6 * 0.6 / (k * 0.001 / math.sqrt(3)), rel=1e-12)
    assert 0.85 < cylinder["l2_um"] < 1.0 and 10.0 < cylinder["l1_um"] < 100.0
    assert cylinder["angle"] == pytest.approx(math.pi / 2)  # ℓ₁ runs across the axis (world x)
    sphere = coherence_at("sphere", radius_m=0.006, distance_m=0.6)
    assert sphere["l1_um"] == pytest.approx(1e6 * 0.6 / (k * 0.003), rel=1e-12)
    assert 12.0 < sphere["l1_um"] < 20.0


def test_tilted_disk_and_rectangle_match_monte_carlo() -> None:
    rng = np.random.default_rng(11)
    direction = unit((0.3, 0.1, 1.0))
    x_axis, y_axis = transverse_frame(direction)
    # Disk: uniform points in the disk's plane (normal n), projected onto the transverse plane.
    normal = unit((0.5, -0.7, 0.4))
    e1 = unit(tuple(np.cross(normal, (0.0, 0.0, 1.0))))
    e2 = np.cross(normal, e1)
    radius = 0.05
    rho = radius * np.sqrt(rng.uniform(size=200_000))
    phi = rng.uniform(0.0, 2 * math.pi, size=200_000)
    points = np.outer(rho * np.cos(phi), e1) + np.outer(rho * np.sin(phi), e2)
    samples = np.stack([points @ x_axis, points @ y_axis], axis=1)
    sxx, sxy, syy = disk_covariance_components(radius, tuple(normal), tuple(x_axis), tuple(y_axis))
    assert_covariance_matches_samples(np.array([[sxx, sxy], [sxy, syy]]), samples)
    # Rectangle w × h with edges u, v (not orthogonal after projection).
    u_axis = unit((1.0, 0.4, 0.3))
    v_axis = unit(tuple(np.cross(u_axis, (0.2, -1.0, 0.5))))
    width, height = 0.08, 0.03
    s = rng.uniform(-0.5, 0.5, size=(200_000, 2))
    points = np.outer(s[:, 0] * width, u_axis) + np.outer(s[:, 1] * height, v_axis)
    samples = np.stack([points @ x_axis, points @ y_axis], axis=1)
    sxx, sxy, syy = rectangle_covariance_components(
        width, height, tuple(u_axis), tuple(v_axis), tuple(x_axis), tuple(y_axis)
    )
    assert_covariance_matches_samples(np.array([[sxx, sxy], [sxy, syy]]), samples)


def test_disk_foreshortening_eigenvalues() -> None:
    # Seen at θ from its normal, a disk is an ellipse with variances R²/4 and R²cos²θ/4. The calculator's
    # disk contains ``axis`` and faces the receiver about it: an axis tilted θ out of the transverse plane
    # puts the normal at θ from the line of sight.
    theta = math.radians(50.0)
    result = transverse_covariance(
        "disk", radius_m=0.02, axis=(0.0, math.cos(theta), -math.sin(theta)), direction=(0.0, 0.0, 1.0)
    )
    np.testing.assert_allclose(
        np.sort(np.linalg.eigvalsh(result.sigma_m2)),
        np.sort([0.02**2 / 4, 0.02**2 * math.cos(theta) ** 2 / 4]),
        rtol=1e-12,
    )


def test_intensity_image_moments() -> None:
    # A uniform block of 10 × 4 pixels in a larger dark image: under the pixel-area model (uniform within
    # each pixel) the block is a uniform w × h rectangle, Σ = diag(w²/12, h²/12) exactly (rounding only).
    pixel = 1e-4
    image = np.zeros((20, 30))
    image[5:9, 7:17] = 3.0
    sigma = covariance_from_intensity_image(image, pixel)
    expected = np.diag([(10 * pixel) ** 2 / 12, (4 * pixel) ** 2 / 12])
    np.testing.assert_allclose(sigma, expected, rtol=0.0, atol=1e-12 * expected[0, 0])
    with pytest.raises(ValueError, match=r"^image:"):
        covariance_from_intensity_image(np.zeros((3, 3)), pixel)
    with pytest.raises(ValueError, match=r"^pixel_size_m:"):
        covariance_from_intensity_image(image, -1.0)


@pytest.mark.parametrize("kind", ["ellipse", "rectangle"])
def test_finite_difference_hessian_reproduces_closed_forms(kind: str) -> None:
    # Rotated ellipse (f̃ = 2J₁(v)/v, v = |diag(a, b) Rᵀζ|) and rectangle (sinc·sinc). Central differences
    # with Richardson extrapolation err by O((h·size)⁴) ≈ (0.05)⁴/24 ≈ 3e-7 relative at h = 0.05/size;
    # rounding adds ~1e-16/(h·size)² ≈ 4e-14. Tolerance 2e-6 relative.
    angle = 0.6
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    a, b = 0.03, 0.012
    if kind == "ellipse":

        def f_tilde(zx: float, zy: float) -> float:
            local = rotation.T @ np.array([zx, zy])
            v = math.hypot(a * local[0], b * local[1])
            return 1.0 if v == 0.0 else 2.0 * j1(v) / v

        expected_local = np.diag([a * a / 4, b * b / 4])
    else:

        def f_tilde(zx: float, zy: float) -> float:
            local = rotation.T @ np.array([zx, zy])
            return float(np.sinc(a * local[0] / (2 * math.pi)) * np.sinc(b * local[1] / (2 * math.pi)))

        expected_local = np.diag([a * a / 12, b * b / 12])
    expected = rotation @ expected_local @ rotation.T
    step = 0.05 / a
    sigma = covariance_from_angular_coherence(f_tilde, step)
    np.testing.assert_allclose(sigma, expected, rtol=0.0, atol=2e-6 * a * a)
    # Lemma 4.4 with its sign: Θ = −H⁻¹ = Σ⁻¹ (positive-definite).
    theta = shape_matrix_from_log_hessian(log_hessian_at_origin(f_tilde, step))
    np.testing.assert_allclose(theta @ expected, np.eye(2), atol=1e-4)


def test_source_coefficients_normalised_real_even_and_symmetric() -> None:
    h0 = hermite_functions(0.0, 12, NUMPY)
    for kind in ("sphere", "cylinder", "disk", "rect", "gaussian"):
        coefficients = source_coefficients(kind, 16)
        at_origin = sum(v * h0[n] * h0[m] for (n, m), v in coefficients.items())
        assert at_origin == pytest.approx(1.0, abs=1e-13)
        for (n, m), value in coefficients.items():
            assert (n + m) % 2 == 0
            assert value == pytest.approx(coefficients[(m, n)], abs=1e-12)  # x ↔ y symmetric kinds
            if n % 2 == 1:  # h_odd is odd: an even function has no (odd, odd) content in these kinds
                assert abs(value) < 1e-12
    assert source_coefficients("sphere", 4) == source_coefficients("disk", 4)
    assert source_coefficients("gaussian", 1) == {(0, 0): pytest.approx(math.sqrt(math.pi), rel=1e-14)}


def test_drjit_covariance_components_equal_numpy() -> None:
    # Float32 evaluation of the same formulas: ~10 operations, rounding ε ≈ 6e-8 each → 1e-5 relative.
    from worker.mitsuba_setup import configured_mitsuba

    mi = configured_mitsuba()
    import drjit as dr

    from worker.render.drjit_ops import drjit_ops

    rng = np.random.default_rng(5)
    axes = rng.normal(size=(32, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    frame = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    jit_axis = tuple(mi.Float(axes[:, i]) for i in range(3))
    jit_frame = tuple(tuple(mi.Float(np.full(32, c)) for c in axis) for axis in frame)
    jit = cylinder_covariance_components(mi.Float(0.01), mi.Float(0.2), jit_axis, *jit_frame, drjit_ops())
    reference = cylinder_covariance_components(0.01, 0.2, tuple(axes.T), *frame, NUMPY)
    scale = 0.2**2 / 12
    for jit_value, ref_value in zip(jit, reference, strict=True):
        np.testing.assert_allclose(np.array(dr.ravel(jit_value)), ref_value, rtol=0.0, atol=1e-5 * scale)
    jit_disk = disk_covariance_components(mi.Float(0.01), jit_axis, *jit_frame)
    ref_disk = disk_covariance_components(0.01, tuple(axes.T), *frame)
    for jit_value, ref_value in zip(jit_disk, ref_disk, strict=True):
        np.testing.assert_allclose(np.array(dr.ravel(jit_value)), ref_value, rtol=0.0, atol=1e-5 * 0.01**2)
    sphere = sphere_covariance_components(mi.Float(0.02))
    np.testing.assert_allclose(np.array(dr.ravel(sphere[0])), 1e-4, rtol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"kind": "sphere"}, "radius_m"),
        ({"kind": "sphere", "radius_m": -1.0}, "radius_m"),
        ({"kind": "sphere", "radius_m": 0.0}, "radius_m"),
        ({"kind": "cylinder", "radius_m": 1.0, "length_m": float("nan")}, "length_m"),
        ({"kind": "rect", "width_m": 1.0}, "height_m"),
        ({"kind": "gaussian", "sigma_m": float("inf")}, "sigma_m"),
        ({"kind": "sphere", "radius_m": 1.0, "direction": (0.0, 0.0, 0.0)}, "direction"),
        ({"kind": "cylinder", "radius_m": 1.0, "length_m": 1.0, "axis": (0.0, 0.0, 0.0)}, "axis"),
        ({"kind": "disk", "radius_m": 1.0, "axis": (0.0, 0.0, 2.0)}, "axis"),
        ({"kind": "cone", "radius_m": 1.0}, "source"),
    ],
)
def test_invalid_source_parameters(kwargs: dict, parameter: str) -> None:
    kind = kwargs.pop("kind")
    with pytest.raises(ValueError, match=rf"^{parameter}:"):
        transverse_covariance(kind, **kwargs)


def test_invalid_mode_counts() -> None:
    for modes in (0, 65, 2.5, True):
        with pytest.raises(ValueError, match=r"^mode_count:"):
            source_coefficients("disk", modes)  # type: ignore[arg-type]


@pytest.mark.parametrize("exit_angle_deg", [0.0, 40.0, 75.0])
def test_scattering_region_disk_consequences(exit_angle_deg: float) -> None:
    # Modelling choice (docs/physics.md §7): a non-specular vertex scatters from a uniform disk of radius a
    # in its tangent plane, seen foreshortened. Leaving at θ from the normal: Σ⊥ eigenvalues a²/4 and
    # a²cos²θ/4, so anisotropy = 1/cos θ and ℓ₁ lies along the projected normal (the narrow direction).
    from hgcore.optics.coherence import coherence_diagnostics

    radius, r = 1e-3, 0.25
    theta = math.radians(exit_angle_deg)
    normal = (0.0, 0.0, 1.0)
    exit_direction = (math.sin(theta), 0.0, math.cos(theta))  # plane of exit: x–z
    x_axis, y_axis = transverse_frame(exit_direction)
    sxx, sxy, syy = disk_covariance_components(radius, normal, tuple(x_axis), tuple(y_axis))
    diagnostics = coherence_diagnostics(np.array([[sxx, sxy], [sxy, syy]]), r)
    assert diagnostics.anisotropy == pytest.approx(1 / math.cos(theta), rel=1e-12)
    k = 2 * math.pi / 550e-9
    assert diagnostics.l2_um == pytest.approx(1e6 * r / (k * radius / 2), rel=1e-12)
    if exit_angle_deg > 0.0:
        l1_axis = math.cos(diagnostics.angle) * x_axis + math.sin(diagnostics.angle) * y_axis
        projected_normal = np.array(normal) - np.dot(normal, exit_direction) * np.array(exit_direction)
        projected_normal /= np.linalg.norm(projected_normal)
        assert abs(float(l1_axis @ projected_normal)) == pytest.approx(1.0, abs=1e-12)
