"""HG expansions (Eqs. 7–8): projection onto the dual basis, reconstruction, real/even coefficients (§4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hgcore.optics.array_ops import transverse_modes
from hgcore.optics.expansion import project_csd, project_onto, reconstruct
from hgcore.optics.hg import hg_functions, multi_indices

ROTATION = np.array([[math.cos(0.4), -math.sin(0.4)], [math.sin(0.4), math.cos(0.4)]])
THETA = ROTATION @ np.diag([1.8, 0.6]) @ ROTATION.T


def test_projection_of_a_finite_hg_series_recovers_its_coefficients() -> None:
    # f = Σ c_α Ψ^Θ_α with known c (orders ≤ 6). Under x = √2Θ^{½}u, f and Ψ̃ each carry e^{−|u|²} and the
    # rule's weight e^{−|u|²} is divided out, so the GH bracket is poly(u)·e^{−|u|²} (degree ≤ 12): entire,
    # with GH remainder ~ g^{(2n)} n!√π/(2ⁿ(2n)!) < 1e-30 for n = 64; rounding leaves ~1e-13.
    rng = np.random.default_rng(3)
    degrees = multi_indices(2, 6)
    truth = {alpha: float(rng.normal()) for alpha in degrees}

    def series(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return reconstruct(truth, THETA, [x, y])

    projected = project_onto(series, THETA, degrees)
    for alpha in degrees:
        assert abs(projected[alpha] - truth[alpha]) < 1e-10, alpha


def test_gaussian_coefficients_closed_form() -> None:
    # f = e^{−½xᵀΘ⁻¹x} = √π |Θ|^{1/4} Ψ^Θ_00 exactly (Eq. 5), so c_00 = √π|Θ|^{1/4}, all others 0.
    inverse = np.linalg.inv(THETA)

    def gaussian(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.exp(-0.5 * (inverse[0, 0] * x * x + 2 * inverse[0, 1] * x * y + inverse[1, 1] * y * y))

    coefficients = project_csd(gaussian, THETA, 16)
    assert list(coefficients) == transverse_modes(16)
    expected = math.sqrt(math.pi) * np.linalg.det(THETA) ** 0.25
    assert abs(coefficients[(0, 0)] - expected) < 1e-12
    assert max(abs(v) for k, v in coefficients.items() if k != (0, 0)) < 1e-12


def test_physical_csd_has_real_even_order_coefficients() -> None:
    # A physical CSD is Hermitian, C(ξ) = C*(−ξ); without the carrier phase it is real and even, so its
    # odd-order coefficients vanish (§4). Quadrature nodes are symmetric under u → −u, so the odd-order
    # sums cancel pairwise up to rounding (~1e-15 × number of nodes).
    inverse = np.linalg.inv(THETA)

    def even_function(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        quadratic = inverse[0, 0] * x * x + 2 * inverse[0, 1] * x * y + inverse[1, 1] * y * y
        return np.exp(-0.3 * quadratic) * np.cos(0.8 * x - 0.5 * y) / (1.0 + 0.1 * quadratic)

    coefficients = project_onto(even_function, THETA, multi_indices(2, 7))
    odd = [abs(v) for alpha, v in coefficients.items() if sum(alpha) % 2 == 1]
    even = [abs(v) for alpha, v in coefficients.items() if sum(alpha) % 2 == 0]
    assert max(odd) < 1e-12
    assert max(even) > 1e-2  # the even ones are genuinely non-zero
    assert all(isinstance(v, float) for v in coefficients.values())


def test_reconstruction_converges_to_a_smooth_csd() -> None:
    # f(x) = e^{−½xᵀΘ⁻¹x}·(1 + 0.2 x₁² − 0.1 x₁x₂): a Gaussian times a quadratic, i.e. exactly a finite HG
    # series of orders ≤ 2 (degree-2 polynomial × Ψ_00 spans Ψ_α, |α| ≤ 2); so 4 modes reproduce it to
    # rounding while 1 mode does not.
    inverse = np.linalg.inv(THETA)

    def f(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        quadratic = inverse[0, 0] * x * x + 2 * inverse[0, 1] * x * y + inverse[1, 1] * y * y
        return np.exp(-0.5 * quadratic) * (1.0 + 0.2 * x * x - 0.1 * x * y)

    points = [np.linspace(-2.0, 2.0, 11), np.linspace(1.5, -1.0, 11)]
    one_mode = reconstruct(project_csd(f, THETA, 1), THETA, points)
    four_modes = reconstruct(project_csd(f, THETA, 4), THETA, points)
    exact = f(*points)
    assert np.max(np.abs(four_modes - exact)) < 1e-12
    assert np.max(np.abs(one_mode - exact)) > 1e-2


def test_reconstruct_matches_hg_functions_directly() -> None:
    coefficients = {(2, 0): 0.5, (0, 0): 1.25}
    x = [np.array([0.3]), np.array([-0.2])]
    values = hg_functions(x, THETA.tolist(), 2)
    np.testing.assert_allclose(
        reconstruct(coefficients, THETA, x), 0.5 * values[(2, 0)] + 1.25 * values[(0, 0)]
    )


def test_invalid_inputs() -> None:
    with pytest.raises(ValueError, match=r"^theta:"):
        project_csd(lambda x, y: x * 0 + 1, [[1.0, 2.0], [2.0, 1.0]], 1)
    with pytest.raises(ValueError, match=r"^theta:"):
        project_csd(lambda x, y: x * 0 + 1, np.eye(3), 1)
    with pytest.raises(ValueError, match=r"^modes:"):
        project_csd(lambda x, y: x * 0 + 1, np.eye(2), 0)
    with pytest.raises(ValueError, match=r"^coefficients:"):
        reconstruct({}, np.eye(2), [np.zeros(1), np.zeros(1)])
