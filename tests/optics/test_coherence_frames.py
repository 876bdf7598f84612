"""The beam's transverse frame (Fig. 5): projection of world x (or a reference), fallbacks, handedness."""

from __future__ import annotations

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.frames import transverse_frame, transverse_frame_components


def assert_right_handed_orthonormal(x_axis: np.ndarray, y_axis: np.ndarray, direction: np.ndarray) -> None:
    frame = np.array([x_axis, y_axis, direction / np.linalg.norm(direction)])
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-12)


def test_default_frame_projects_world_x() -> None:
    x_axis, y_axis = transverse_frame((0.0, 0.0, 1.0))
    np.testing.assert_allclose(x_axis, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(y_axis, [0.0, 1.0, 0.0])
    direction = np.array([0.3, -0.4, 0.5])
    x_axis, y_axis = transverse_frame(direction)
    unit = direction / np.linalg.norm(direction)
    projected = np.array([1.0, 0.0, 0.0]) - unit[0] * unit
    np.testing.assert_allclose(x_axis, projected / np.linalg.norm(projected), atol=1e-15)
    assert_right_handed_orthonormal(x_axis, y_axis, direction)


@pytest.mark.parametrize("direction", [(1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (1.0, 1e-5, 0.0)])
def test_world_x_parallel_falls_back_to_world_y(direction: tuple[float, float, float]) -> None:
    x_axis, y_axis = transverse_frame(direction)
    assert abs(x_axis[1]) > 0.999  # the projection of world y
    assert x_axis[1] > 0.0
    assert_right_handed_orthonormal(x_axis, y_axis, np.array(direction))


def test_reference_vector_and_its_fallback() -> None:
    direction = np.array([0.0, 0.0, -1.0])
    x_axis, _ = transverse_frame(direction, reference=(0.0, 2.0, 0.0))
    np.testing.assert_allclose(x_axis, [0.0, 1.0, 0.0])
    x_axis, y_axis = transverse_frame(direction, reference=(0.0, 0.0, 3.0))  # parallel: world x instead
    np.testing.assert_allclose(x_axis, [1.0, 0.0, 0.0])
    assert_right_handed_orthonormal(x_axis, y_axis, direction)


def test_vectorised_components_match_scalar_frames() -> None:
    rng = np.random.default_rng(4)
    directions = rng.normal(size=(20, 3))
    directions[0] = (1.0, 0.0, 0.0)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    x_axis, y_axis = transverse_frame_components(tuple(directions.T), ops=NUMPY)
    for i, direction in enumerate(directions):
        expected_x, expected_y = transverse_frame(direction)
        np.testing.assert_allclose([c[i] for c in x_axis], expected_x, atol=1e-14)
        np.testing.assert_allclose([c[i] for c in y_axis], expected_y, atol=1e-14)


def test_invalid_vectors() -> None:
    with pytest.raises(ValueError, match=r"^direction:"):
        transverse_frame((0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^direction:"):
        transverse_frame((0.0, float("nan"), 1.0))
    with pytest.raises(ValueError, match=r"^reference:"):
        transverse_frame((0.0, 0.0, 1.0), reference=(1.0, 0.0))


def test_drjit_frame_equals_numpy() -> None:
    # Same arithmetic in float32 (ε ≈ 6e-8; ~10 operations and one rsqrt): 1e-6 absolute on unit vectors.
    from worker.mitsuba_setup import configured_mitsuba

    mi = configured_mitsuba()
    import drjit as dr

    from worker.render.drjit_ops import drjit_ops

    rng = np.random.default_rng(9)
    directions = rng.normal(size=(16, 3))
    reference = (0.0, 0.6, 0.8)
    directions[0] = reference  # parallel to the reference: exercises the world-x fallback in the kernel
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    jit_x, jit_y = transverse_frame_components(
        tuple(mi.Float(directions[:, i]) for i in range(3)), reference, drjit_ops()
    )
    for i, direction in enumerate(directions):
        expected_x, expected_y = transverse_frame(direction, reference)
        np.testing.assert_allclose([float(dr.ravel(c)[i]) for c in jit_x], expected_x, atol=1e-6)
        np.testing.assert_allclose([float(dr.ravel(c)[i]) for c in jit_y], expected_y, atol=1e-6)
