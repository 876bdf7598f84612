"""Anisotropic HG functions (Eqs. 5, 6, 8, 9): recurrence vs symbolic Eq. 5, biorthogonality, Fourier pairs.

All quadratures are Gauss–Hermite (GH) rules after the change of variables that turns the Gaussian factor
into e^{−|u|²}; each test states why its rule is exact or how fast its error decays.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from hgcore.optics.array_ops import NUMPY, hermite_functions
from hgcore.optics.hg import dual_hg_functions, hg_functions, multi_indices

# A rotated (30°), anisotropic (eigenvalues 2.5 and 0.4) shape matrix: Ψ^Θ is not a product of 1-D functions.
ROTATION = np.array([[math.cos(0.5236), -math.sin(0.5236)], [math.sin(0.5236), math.cos(0.5236)]])
THETA_2D = ROTATION @ np.diag([2.5, 0.4]) @ ROTATION.T
THETA_3D = np.array([[1.7, 0.3, -0.2], [0.3, 0.9, 0.25], [-0.2, 0.25, 0.6]])


def symmetric_sqrt(matrix: np.ndarray) -> np.ndarray:
    eigenvalues, eigenvectors = np.linalg.eigh(matrix)
    return (eigenvectors * np.sqrt(eigenvalues)) @ eigenvectors.T


def gauss_hermite_grid(points: int, dimension: int) -> tuple[np.ndarray, np.ndarray]:
    nodes, weights = np.polynomial.hermite.hermgauss(points)
    grid = np.stack([g.ravel() for g in np.meshgrid(*([nodes] * dimension), indexing="ij")])
    weight = np.prod(np.meshgrid(*([weights] * dimension), indexing="ij"), axis=0).ravel()
    return grid, weight


def test_identity_shape_matrix_factorises_into_hermite_functions() -> None:
    # For Θ = I, Eq. (5) is Π h_{α_i}(x_i) (paper Eq. S1.1); both are recurrences in float64 → ~1e-15.
    x = np.linspace(-3.0, 3.0, 7)
    y = np.linspace(-2.5, 2.0, 7)
    values = hg_functions([x, y], np.eye(2).tolist(), 16)
    hx, hy = hermite_functions(x, 16), hermite_functions(y, 16)
    for (n, m), value in values.items():
        np.testing.assert_allclose(value, hx[n] * hy[m], rtol=0.0, atol=1e-13)


@pytest.mark.parametrize("alpha", [(0, 0), (1, 0), (0, 3), (2, 2), (8, 0), (3, 5), (8, 8)])
def test_recurrence_matches_symbolic_derivatives_of_eq5(alpha: tuple[int, int]) -> None:
    # Eq. (5) differentiated symbolically by sympy with an exact rational A = Θ⁻¹ (off-diagonal: anisotropic
    # and rotated), evaluated in float64. The recurrence rounds ~|α| times per term; terms of both signs
    # cancel by up to ~1e3 at order 16, so agreement to 1e-10 of the largest |Ψ| on the points is expected.
    x_symbol, y_symbol = sp.symbols("x y", real=True)
    inverse = sp.Matrix([[sp.Rational(3, 5), sp.Rational(-1, 5)], [sp.Rational(-1, 5), sp.Rational(2, 5)]])
    vector = sp.Matrix([x_symbol, y_symbol])
    quadratic = (vector.T * inverse * vector)[0]
    n, m = alpha
    order = n + m
    derivative = sp.exp(-quadratic)
    if n:
        derivative = sp.diff(derivative, x_symbol, n)
    if m:
        derivative = sp.diff(derivative, y_symbol, m)
    determinant_theta = 1 / inverse.det()
    expression = (
        (-1) ** order
        / (sp.sqrt(sp.pi) * 2 ** sp.Rational(order, 2) * sp.sqrt(sp.factorial(n) * sp.factorial(m)))
        * sp.exp(quadratic / 2)
        * derivative
        / determinant_theta ** sp.Rational(1, 4)
    )
    evaluate = sp.lambdify((x_symbol, y_symbol), expression, "numpy")
    points_x = np.array([0.0, 0.7, -1.3, 2.1, -0.4, 3.0])
    points_y = np.array([0.0, -0.9, 0.5, 1.7, -2.2, 0.3])
    expected = np.array([float(evaluate(px, py)) for px, py in zip(points_x, points_y, strict=True)])
    theta = np.array(inverse.inv().tolist(), dtype=float)
    actual = hg_functions([points_x, points_y], theta.tolist(), order)[alpha]
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=1e-10 * np.max(np.abs(expected)))


def test_biorthogonality_eq8_rotated_anisotropic_orders_up_to_8() -> None:
    # ⟨Ψ^Θ_α | Ψ̃^Θ_β⟩ = δ_αβ. Both carry e^{−½xᵀΘ⁻¹x}; with x = Θ^{½}u the integrand is a polynomial of
    # degree |α| + |β| ≤ 16 times e^{−|u|²}, which a 12-point GH rule per axis integrates exactly (degree
    # ≤ 23). Only rounding remains: ~1e-13 relative to the largest products summed.
    grid, weight = gauss_hermite_grid(12, 2)
    x = symmetric_sqrt(THETA_2D) @ grid
    weight = weight * np.exp(np.sum(grid * grid, axis=0)) * math.sqrt(np.linalg.det(THETA_2D))
    primal = hg_functions(list(x), THETA_2D.tolist(), 8)
    dual = dual_hg_functions(list(x), THETA_2D.tolist(), 8)
    degrees = multi_indices(2, 8)
    gram = np.array([[np.sum(weight * primal[a] * dual[b]) for b in degrees] for a in degrees])
    np.testing.assert_allclose(gram, np.eye(len(degrees)), rtol=0.0, atol=1e-9)


def test_biorthogonality_3d_spot_check() -> None:
    # Same argument in 3-D: degrees up to |α| = 4, products of degree ≤ 8, exact with 6 GH points per axis.
    grid, weight = gauss_hermite_grid(6, 3)
    x = symmetric_sqrt(THETA_3D) @ grid
    weight = weight * np.exp(np.sum(grid * grid, axis=0)) * math.sqrt(np.linalg.det(THETA_3D))
    primal = hg_functions(list(x), THETA_3D.tolist(), 4)
    dual = dual_hg_functions(list(x), THETA_3D.tolist(), 4)
    degrees = multi_indices(3, 4)
    gram = np.array([[np.sum(weight * primal[a] * dual[b]) for b in degrees] for a in degrees])
    np.testing.assert_allclose(gram, np.eye(len(degrees)), rtol=0.0, atol=1e-10)


@pytest.mark.parametrize("alpha", [(0, 0), (1, 0), (0, 1), (2, 1), (4, 2), (5, 3), (0, 8), (8, 0)])
def test_fourier_pair_eq9(alpha: tuple[int, int]) -> None:
    # F{Ψ^Θ_α}(ζ) = ∫Ψ^Θ_α(x) e^{−iζ·x} dx = 2π (−i)^{|α|} Ψ̃^{Θ⁻¹}_α(ζ) in 2-D. With x = √2 Θ^{½} u the
    # integrand is poly(u) e^{−i ω·u} e^{−|u|²}, |ω| = √2 |Θ^{½}ζ| ≤ 4 here. The n-point GH remainder is
    # g^{(2n)} n! √π / (2ⁿ (2n)!); for g = poly·e^{iω·u} with |ω| ≤ 4 and n = 64 it is < 1e-40, so only
    # float64 rounding of the ~4000 summed terms (each ≲ 1) remains: tolerance 1e-10.
    grid, weight = gauss_hermite_grid(64, 2)
    transform = math.sqrt(2.0) * symmetric_sqrt(THETA_2D)
    x = transform @ grid
    weight = weight * np.exp(np.sum(grid * grid, axis=0)) * abs(np.linalg.det(transform))
    primal = hg_functions(list(x), THETA_2D.tolist(), sum(alpha))[alpha]
    zetas = np.array([[0.0, 0.0], [0.6, -0.3], [-1.1, 0.8], [0.2, 1.5]])
    inverse_theta = np.linalg.inv(THETA_2D)
    for zeta in zetas:
        numeric = np.sum(weight * primal * np.exp(-1j * (zeta @ x)))
        expected = (
            2.0
            * math.pi
            * (-1j) ** sum(alpha)
            * dual_hg_functions([zeta[0], zeta[1]], inverse_theta.tolist(), sum(alpha))[alpha]
        )
        assert abs(numeric - expected) < 1e-10, (zeta, numeric, expected)


def test_drjit_evaluation_equals_numpy() -> None:
    # The same recurrence on Dr.Jit single-precision arrays (the integrator's mi.Float). Float32 rounding
    # (ε ≈ 6e-8) accumulated over ~16 recurrence steps with cancellation ≲ 1e2 gives ≲ 1e-4 relative to the
    # largest |Ψ|; entries of Θ are passed as separate Python floats.
    from worker.mitsuba_setup import configured_mitsuba

    mi = configured_mitsuba()
    import drjit as dr

    from worker.render.drjit_ops import drjit_ops

    rng = np.random.default_rng(7)
    x_np = rng.uniform(-2.5, 2.5, 64)
    y_np = rng.uniform(-2.5, 2.5, 64)
    reference = hg_functions([x_np, y_np], THETA_2D.tolist(), 12, NUMPY)
    jit = hg_functions([mi.Float(x_np), mi.Float(y_np)], THETA_2D.tolist(), 12, drjit_ops())
    jit_dual = dual_hg_functions([mi.Float(x_np), mi.Float(y_np)], THETA_2D.tolist(), 12, drjit_ops())
    reference_dual = dual_hg_functions([x_np, y_np], THETA_2D.tolist(), 12, NUMPY)
    for alpha in [(0, 0), (2, 0), (3, 3), (12, 0), (5, 7)]:
        scale = np.max(np.abs(reference[alpha]))
        np.testing.assert_allclose(np.array(dr.ravel(jit[alpha])), reference[alpha], atol=1e-4 * scale)
        scale_dual = np.max(np.abs(reference_dual[alpha]))
        np.testing.assert_allclose(
            np.array(dr.ravel(jit_dual[alpha])), reference_dual[alpha], atol=1e-4 * scale_dual
        )


def test_bad_inputs_raise_value_errors_naming_the_parameter() -> None:
    with pytest.raises(ValueError, match=r"^x:"):
        hg_functions([1.0], [[1.0]], 2)
    with pytest.raises(ValueError, match=r"^theta:"):
        hg_functions([1.0, 2.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], 2)
    with pytest.raises(ValueError, match=r"^max_order:"):
        multi_indices(2, -1)
