"""Propagation (§5): free space grows r; perfect mirrors/refraction keep Θ, carry the frame, accumulate r."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hgcore.optics.propagation import CoherenceState
from hgcore.optics.sources import source_coefficients, transverse_covariance

WAVELENGTH_M = 550e-9
K = 2 * math.pi / WAVELENGTH_M


def cylinder_state(distance_m: float) -> CoherenceState:
    covariance = transverse_covariance(
        "cylinder", radius_m=1e-3, length_m=0.2, axis=(1.0, 1.0, 0.0), direction=(0.0, 0.0, 1.0)
    )
    return CoherenceState.from_source(covariance, distance_m, source_coefficients("cylinder", 4))


def test_free_space_grows_r_only() -> None:
    state = cylinder_state(0.5)
    later = state.propagated(1.5)
    assert later.r_m == pytest.approx(2.0)
    np.testing.assert_array_equal(later.sigma_m2, state.sigma_m2)
    np.testing.assert_allclose(later.theta_per_m2, np.linalg.inv(state.sigma_m2))
    # ℓ = r/(k·s) ∝ r (Fig. 5: the coherence area grows ∝ (r/k)²).
    assert later.diagnostics().l1_um / state.diagnostics().l1_um == pytest.approx(4.0, rel=1e-12)
    assert later.diagnostics().area_um2 / state.diagnostics().area_um2 == pytest.approx(16.0, rel=1e-12)


def test_mirror_chain_keeps_coherence_length_proportional_to_total_path() -> None:
    # Source → 0.4 m → mirror → 0.7 m → mirror → 0.9 m: ℓ₁, ℓ₂ equal the straight-line values at 2.0 m
    # (closed form r/(k s) with the source's principal std s), and scale ∝ the accumulated path.
    legs = [0.4, 0.7, 0.9]
    normals = [(0.0, 0.3, -1.0), (0.5, -0.2, 1.0)]
    state = cylinder_state(legs[0])
    lengths = [state.diagnostics().l1_um]
    for normal, leg in zip(normals, legs[1:], strict=True):
        state = state.reflected(normal).propagated(leg)
        lengths.append(state.diagnostics().l1_um)
    assert state.r_m == pytest.approx(sum(legs))
    radius_std = 1e-3 / math.sqrt(3.0)  # across the side-on strip: R²/3
    length_std = 0.2 / math.sqrt(12.0)
    diagnostics = state.diagnostics()
    # The axis lies at 45° in the frame, so m₋ = (ac − b²)/m₊ cancels: relative rounding ≈ ε·anisotropy²
    # = 2e-16·1e4 ≈ 2e-12 per operation; allow 1e-9.
    assert diagnostics.l1_um == pytest.approx(1e6 * sum(legs) / (K * radius_std), rel=1e-9)
    assert diagnostics.l2_um == pytest.approx(1e6 * sum(legs) / (K * length_std), rel=1e-9)
    np.testing.assert_allclose(np.array(lengths) / lengths[0], np.cumsum(legs) / legs[0], rtol=1e-9)


def test_reflection_maps_the_coherence_ellipse_with_the_mirror() -> None:
    # The ℓ₁ axis (a physical transverse direction) must be the mirror image of the incident one, and the
    # reflected frame stays right-handed.
    state = cylinder_state(1.0)
    normal = np.array([0.2, -0.3, -1.0])
    normal /= np.linalg.norm(normal)
    reflected = state.reflected(normal)
    householder = np.eye(3) - 2 * np.outer(normal, normal)
    np.testing.assert_allclose(reflected.direction, householder @ state.direction, atol=1e-15)
    frame = np.array([reflected.x_axis, reflected.y_axis, reflected.direction])
    assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-12)

    def l1_axis_world(s: CoherenceState) -> np.ndarray:
        angle = s.diagnostics().angle
        return math.cos(angle) * s.x_axis + math.sin(angle) * s.y_axis

    mirrored = householder @ l1_axis_world(state)
    assert abs(float(mirrored @ l1_axis_world(reflected))) == pytest.approx(1.0, abs=1e-12)


def test_refraction_keeps_theta_and_turns_the_frame() -> None:
    state = cylinder_state(0.3)
    normal = (0.0, math.sin(0.5), -math.cos(0.5))  # 0.5 rad incidence, normal facing the beam
    refracted = state.refracted(normal, 1.5)
    sin_t = math.sin(0.5) / 1.5  # Snell
    assert math.asin(
        float(np.linalg.norm(np.cross(refracted.direction, -np.array(normal))))
    ) == pytest.approx(math.asin(sin_t), abs=1e-12)
    np.testing.assert_array_equal(refracted.sigma_m2, state.sigma_m2)
    assert refracted.r_m == state.r_m
    frame = np.array([refracted.x_axis, refracted.y_axis, refracted.direction])
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert refracted.propagated(0.7).diagnostics().l1_um == pytest.approx(
        state.propagated(0.7).diagnostics().l1_um, rel=1e-12
    )
    with pytest.raises(ValueError, match=r"^relative_ior:"):
        state.refracted((0.0, math.sin(1.2), -math.cos(1.2)), 1 / 1.5)  # beyond the critical angle


def test_in_frame_rotates_sigma_consistently() -> None:
    state = cylinder_state(1.0)
    angle = 0.3
    new_x = math.cos(angle) * state.x_axis + math.sin(angle) * state.y_axis
    rotated = state.in_frame(new_x)
    assert rotated.diagnostics().angle == pytest.approx(state.diagnostics().angle - angle, abs=1e-12)
    assert rotated.diagnostics().l1_um == pytest.approx(state.diagnostics().l1_um, rel=1e-12)
    xi = (2e-6, -1e-6)
    xi_new = (
        xi[0] * math.cos(angle) + xi[1] * math.sin(angle),
        -xi[0] * math.sin(angle) + xi[1] * math.cos(angle),
    )
    assert rotated.degree_of_coherence(xi_new) == pytest.approx(state.degree_of_coherence(xi), abs=1e-12)
    with pytest.raises(ValueError, match=r"^x_axis:"):
        state.in_frame(state.direction)


def test_state_validation() -> None:
    covariance = transverse_covariance("sphere", radius_m=1e-3)
    with pytest.raises(ValueError, match=r"^r_m:"):
        CoherenceState.from_source(covariance, 0.0)
    state = CoherenceState.from_source(covariance, 1.0)
    with pytest.raises(ValueError, match=r"^distance_m:"):
        state.propagated(-1.0)
    with pytest.raises(ValueError, match=r"^normal:"):
        state.reflected((0.0, 0.0, 0.0))
