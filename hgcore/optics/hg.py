"""Anisotropic Hermite-Gauss functions Ψ^Θ_α (Eq. 5) and their duals Ψ̃^Θ_α (Eq. 6), in 2 or 3 dimensions.

Eq. (5) in d dimensions, A = Θ⁻¹, |α| = Σα_i, α! = Πα_i!:

    Ψ^Θ_α(x) = (−1)^{|α|} / (π^{d/4} 2^{|α|/2} √α!) · e^{½xᵀAx} ∂^α e^{−xᵀAx} / |Θ|^{1/4}.

Evaluated by a value recurrence, never by symbolic differentiation. With D_α = e^{xᵀAx} ∂^α e^{−xᵀAx},
∂_i e^{−xᵀAx} = −2(Ax)_i e^{−xᵀAx} and Leibniz's rule give D_{α+e_i} = −2 Σ_j A_ij (x_j D_α + α_j D_{α−e_j}).
Folding the normalisation in (P_α = Ψ^Θ_α) turns this into

    Ψ_{α+e_i} = (1/√(α_i+1)) Σ_j A_ij (√2 x_j Ψ_α − √α_j Ψ_{α−e_j}),   Ψ_0 = e^{−½xᵀAx}/(π^{d/4}|Θ|^{1/4}),

which for d = 1, Θ = 1 is the familiar Hermite-function recurrence; no factorial or power of 2 is formed,
so orders up to 16 stay in range. Dual (Eq. 6): Ψ̃^Θ_α(x) = |Θ|^{−½} Ψ^{Θ⁻¹}_α(Θ⁻¹x).

Units: x and Θ must be reciprocal (e.g. x = k/r·ξ in 1/m with Θ in 1/m²); Ψ^Θ has units |Θ|^{−1/4}·A^{|α|/2}.
The functions take x as a sequence of d scalars/arrays and Θ as nested d×d entries (scalars or arrays), and an
``ops`` namespace, so they run on NumPy and inside Dr.Jit kernels.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY, ArrayOps

MultiIndex = tuple[int, ...]
Matrix = Sequence[Sequence[Any]]


def multi_indices(dimension: int, max_order: int) -> list[MultiIndex]:
    """All degrees α ∈ ℕ^dimension with |α| ≤ max_order, by increasing order then lexicographically."""
    if dimension not in (2, 3):
        raise InputError(f"dimension: must be 2 or 3, got {dimension}")
    if max_order < 0:
        raise InputError(f"max_order: must be non-negative, got {max_order}")
    indices = [a for a in itertools.product(range(max_order + 1), repeat=dimension) if sum(a) <= max_order]
    return sorted(indices, key=lambda a: (sum(a), tuple(-c for c in a)))


def inverse_and_determinant(matrix: Matrix) -> tuple[list[list[Any]], Any]:
    """Inverse and determinant of a 2×2 or 3×3 matrix by cofactors (element-wise: works on arrays)."""
    size = len(matrix)
    if size == 2:
        (a, b), (c, d) = matrix
        det = a * d - b * c
        inv_det = 1.0 / det
        return [[d * inv_det, -b * inv_det], [-c * inv_det, a * inv_det]], det
    if size == 3:
        m = matrix
        cofactor = [
            [
                m[(i + 1) % 3][(j + 1) % 3] * m[(i + 2) % 3][(j + 2) % 3]
                - m[(i + 1) % 3][(j + 2) % 3] * m[(i + 2) % 3][(j + 1) % 3]
                for j in range(3)
            ]
            for i in range(3)
        ]
        det = m[0][0] * cofactor[0][0] + m[0][1] * cofactor[0][1] + m[0][2] * cofactor[0][2]
        inv_det = 1.0 / det
        # inverse = adjugate / det, adjugate = cofactorᵀ.
        return [[cofactor[j][i] * inv_det for j in range(3)] for i in range(3)], det
    raise InputError(f"theta: must be 2x2 or 3x3, got {size}x{size}")


def _hg_from_inverse(
    x: Sequence[Any], inverse: list[list[Any]], determinant: Any, max_order: int, ops: ArrayOps
) -> dict[MultiIndex, Any]:
    """Ψ^Θ_α(x) for all |α| ≤ max_order given A = Θ⁻¹ and |Θ| (the recurrence of the module docstring)."""
    dimension = len(x)
    quadratic = 0.0
    for i in range(dimension):
        for j in range(dimension):
            quadratic = quadratic + x[i] * inverse[i][j] * x[j]
    values: dict[MultiIndex, Any] = {
        (0,) * dimension: ops.exp(-0.5 * quadratic)
        * (math.pi ** (-dimension / 4.0))
        / ops.sqrt(ops.sqrt(determinant))
    }
    sqrt2 = math.sqrt(2.0)
    for alpha in multi_indices(dimension, max_order)[1:]:
        axis = next(i for i, a in enumerate(alpha) if a > 0)
        parent = tuple(a - (1 if i == axis else 0) for i, a in enumerate(alpha))
        total: Any = 0.0
        for j in range(dimension):
            term = sqrt2 * x[j] * values[parent]
            if parent[j] > 0:
                grandparent = tuple(a - (1 if i == j else 0) for i, a in enumerate(parent))
                term = term - math.sqrt(parent[j]) * values[grandparent]
            total = total + inverse[axis][j] * term
        values[alpha] = total * (1.0 / math.sqrt(parent[axis] + 1))
    return values


def hg_functions(
    x: Sequence[Any], theta: Matrix, max_order: int, ops: ArrayOps = NUMPY
) -> dict[MultiIndex, Any]:
    """Ψ^Θ_α(x) (Eq. 5) for every degree α with |α| ≤ ``max_order``, keyed by α.

    ``x``: d = 2 or 3 coordinates (scalars or arrays); ``theta``: the d×d positive-definite shape matrix.
    """
    _check_dimensions(x, theta)
    inverse, determinant = inverse_and_determinant(theta)
    return _hg_from_inverse(x, inverse, determinant, max_order, ops)


def dual_hg_functions(
    x: Sequence[Any], theta: Matrix, max_order: int, ops: ArrayOps = NUMPY
) -> dict[MultiIndex, Any]:
    """Ψ̃^Θ_α(x) = |Θ|^{−½} Ψ^{Θ⁻¹}_α(Θ⁻¹x) (Eq. 6) for every |α| ≤ ``max_order``."""
    _check_dimensions(x, theta)
    inverse, determinant = inverse_and_determinant(theta)
    dimension = len(x)
    transformed = [sum((inverse[i][j] * x[j] for j in range(dimension)), 0.0) for i in range(dimension)]
    # Ψ^{Θ⁻¹} needs (Θ⁻¹)⁻¹ = Θ and |Θ⁻¹| = 1/|Θ|.
    values = _hg_from_inverse(transformed, [list(row) for row in theta], 1.0 / determinant, max_order, ops)
    scale = 1.0 / ops.sqrt(determinant)
    return {alpha: value * scale for alpha, value in values.items()}


def _check_dimensions(x: Sequence[Any], theta: Matrix) -> None:
    dimension = len(x)
    if dimension not in (2, 3):
        raise InputError(f"x: must have 2 or 3 coordinates, got {dimension}")
    if len(theta) != dimension or any(len(row) != dimension for row in theta):
        raise InputError(f"theta: must be {dimension}x{dimension} to match x")
