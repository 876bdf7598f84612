"""The beam's local frame: transverse axes for a propagation direction (paper Fig. 5, Def. 4.1's Q).

For a unit propagation direction d the transverse x axis is the normalised projection of a reference vector
(world x by default; the integrator passes the camera's right vector) onto the plane ⟂ d. When the reference
is (nearly) parallel to d the projection of world x is used instead, and if that too is degenerate the
projection of world y. The y axis is y = d × x, so (x, y, d) is right-handed. Rows of Q in Def. 4.1 are
(x, y, d). All vectors are dimensionless unit vectors.

The component form (``transverse_frame_components``) takes 3-tuples of scalars or arrays and runs on NumPy
and inside Dr.Jit kernels; ``transverse_frame`` is the validated NumPy convenience wrapper.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY, ArrayOps

Vector3 = tuple[Any, Any, Any]

# A reference whose projection onto the transverse plane is shorter than this (squared: 1e-6, i.e. within
# ~0.06° of d) is "nearly parallel": normalising it would amplify rounding into a random axis.
_PARALLEL_PROJECTION_SQUARED = 1e-6

WORLD_X: Vector3 = (1.0, 0.0, 0.0)
WORLD_Y: Vector3 = (0.0, 1.0, 0.0)


def dot3(a: Vector3, b: Vector3) -> Any:
    """a · b for 3-tuples of scalars/arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross3(a: Vector3, b: Vector3) -> Vector3:
    """a × b for 3-tuples of scalars/arrays."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _project_transverse(vector: Vector3, direction: Vector3) -> tuple[Vector3, Any]:
    """The projection of ``vector`` onto the plane ⟂ direction and its squared length."""
    along = dot3(vector, direction)
    projected = (
        vector[0] - along * direction[0],
        vector[1] - along * direction[1],
        vector[2] - along * direction[2],
    )
    return projected, dot3(projected, projected)


def transverse_frame_components(
    direction: Vector3, reference: Vector3 = WORLD_X, ops: ArrayOps = NUMPY
) -> tuple[Vector3, Vector3]:
    """Transverse axes (x_axis, y_axis) for unit ``direction`` (component form, NumPy or Dr.Jit).

    ``reference`` is projected onto the transverse plane; where it is nearly parallel to the direction the
    world x axis is used, and where that is too, the world y axis (which then cannot be parallel as well).
    """
    candidate, length2 = _project_transverse(reference, direction)
    world_x, world_x_length2 = _project_transverse(WORLD_X, direction)
    world_y, world_y_length2 = _project_transverse(WORLD_Y, direction)
    use_reference = length2 > _PARALLEL_PROJECTION_SQUARED
    use_world_x = world_x_length2 > _PARALLEL_PROJECTION_SQUARED
    fallback = tuple(ops.where(use_world_x, world_x[i], world_y[i]) for i in range(3))
    fallback_length2 = ops.where(use_world_x, world_x_length2, world_y_length2)
    chosen = tuple(ops.where(use_reference, candidate[i], fallback[i]) for i in range(3))
    chosen_length2 = ops.where(use_reference, length2, fallback_length2)
    inverse_length = 1.0 / ops.sqrt(chosen_length2)
    x_axis = (chosen[0] * inverse_length, chosen[1] * inverse_length, chosen[2] * inverse_length)
    y_axis = cross3(direction, x_axis)
    return x_axis, y_axis


def unit_vector(vector: Sequence[float], name: str) -> np.ndarray:
    """``vector`` as a normalised float64 3-vector; ValueError naming ``name`` if not finite/non-zero."""
    array = np.asarray(vector, dtype=float)
    if array.shape != (3,):
        raise InputError(f"{name}: expected 3 components X,Y,Z, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: components must be finite numbers, got {array.tolist()}")
    length = float(np.linalg.norm(array))
    if length <= 1e-12:
        raise InputError(f"{name}: must be a non-zero vector, got {array.tolist()}")
    return array / length


def transverse_frame(
    direction: Sequence[float], reference: Sequence[float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Transverse (x_axis, y_axis) of a propagation ``direction`` (normalised here), as NumPy 3-vectors."""
    unit_direction = unit_vector(direction, "direction")
    unit_reference = WORLD_X if reference is None else tuple(unit_vector(reference, "reference"))
    x_axis, y_axis = transverse_frame_components(tuple(unit_direction), tuple(unit_reference), NUMPY)
    return np.array([float(c) for c in x_axis]), np.array([float(c) for c in y_axis])
