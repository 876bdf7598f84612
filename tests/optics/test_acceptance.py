"""``hgcore.optics.acceptance``: a rough lobe's acceptance and its product with a uniform source."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hgcore.optics.acceptance import (
    ELLIPSE_OFFSET_SCALE,
    flat_top_product_components,
    lobe_acceptance_variance,
    product_components,
)
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.rough_surface import RoughSurface


def truncated_variance_by_quadrature(surface: RoughSurface, wavelength_m: float) -> float:
    """Per-axis variance of β over |β| < 1 weighted by S(β/λ) (the lobe about its centre), radially."""
    radius = np.linspace(0.0, 1.0, 400_001)[1:]
    frequency2 = (radius / wavelength_m) ** 2
    if surface.psd_model == "gaussian":
        density = np.exp(-((math.pi * surface.correlation_length_m) ** 2) * frequency2)
    else:
        density = (1.0 + surface.abc_b_m**2 * frequency2) ** (-(surface.abc_exponent + 1.0) / 2.0)
    weight = radius * density
    return float(np.trapezoid(weight * radius**2 / 2.0, radius) / np.trapezoid(weight, radius))


@pytest.mark.parametrize(
    "surface",
    [
        RoughSurface(0.1e-6, 2.0e-6),
        RoughSurface(0.1e-6, 0.3e-6),  # a lobe as wide as the horizon
        RoughSurface(0.3e-6, 0.5e-6, "abc", 1.2),  # no untruncated second moment
        RoughSurface(0.3e-6, 0.5e-6, "abc", 3.0),  # the logarithmic case
        RoughSurface(0.1e-6, 5.0e-6, "abc", 3.5),
    ],
)
@pytest.mark.parametrize("wavelength_nm", [400.0, 700.0])
def test_lobe_acceptance_variance_is_the_truncated_lobe_s(
    surface: RoughSurface, wavelength_nm: float
) -> None:
    closed_form = float(lobe_acceptance_variance(surface, 1.0, wavelength_nm * 1e-9, NUMPY))
    assert closed_form == pytest.approx(
        truncated_variance_by_quadrature(surface, wavelength_nm * 1e-9), rel=2e-3
    )


def test_a_gaussian_lobe_narrow_against_the_horizon_has_its_psd_s_variance() -> None:
    """s = λ/(√2 π ℓc): the sampled frequency's per-axis std times λ (rough_surface.sample_psd_frequency)."""
    surface = RoughSurface(0.1e-6, 5.0e-6)
    expected = (550e-9 / (math.sqrt(2.0) * math.pi * 5e-6)) ** 2
    assert float(lobe_acceptance_variance(surface, 1.0, 550e-9, NUMPY)) == pytest.approx(expected, rel=1e-9)


SOURCE = (0.0, 0.0), (0.0016, 0.0, 0.0016)  # a uniform disk of angular radius 0.08


def product(acceptance_mean, acceptance_cov, unbounded=False):
    mean, cov = flat_top_product_components(
        *SOURCE, acceptance_mean, acceptance_cov, unbounded, ELLIPSE_OFFSET_SCALE, NUMPY
    )
    return np.array([float(m) for m in mean]), np.array([float(c) for c in cov])


def test_the_flat_top_product_has_the_exact_limits() -> None:
    # one direction passed (a specular interaction): that direction, no spread
    mean, cov = product((0.02, -0.01), (0.0, 0.0, 0.0))
    assert mean == pytest.approx([0.02, -0.01], abs=1e-12) and cov == pytest.approx([0, 0, 0], abs=1e-15)
    # an acceptance that covers the source: the source itself
    for unbounded, covariance in ((True, (1e-6, 0.0, 1e-6)), (False, (1e4, 0.0, 1e4))):
        mean, cov = product((0.3, 0.2), covariance, unbounded)
        assert mean == pytest.approx([0.0, 0.0], abs=1e-4) and cov == pytest.approx(
            [0.0016, 0.0, 0.0016], rel=1e-3, abs=1e-9
        )
    # a point source (a secondary source's point): the point, no spread
    mean, cov = flat_top_product_components(
        (0.01, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0), (1e-3, 0.0, 1e-3), False, ELLIPSE_OFFSET_SCALE, NUMPY
    )
    assert [float(m) for m in mean] == pytest.approx([0.01, 0.0]) and [
        float(c) for c in cov
    ] == pytest.approx([0, 0, 0], abs=1e-15)


def test_a_narrow_lobe_inside_a_flat_source_is_not_pulled_towards_its_centre() -> None:
    """The Gaussian product pulls by K = C_a/(C_a + C_s) of the offset; a flat source does not pull."""
    acceptance = (0.03, 0.0), (1e-5, 0.0, 1e-5)
    mean, cov = product(*acceptance)
    assert mean[0] == pytest.approx(0.03, abs=1e-6) and cov[0] == pytest.approx(1e-5, rel=1e-3)
    gaussian_mean, _ = product_components(*SOURCE, *acceptance, False, NUMPY)
    assert float(gaussian_mean[0]) < 0.03 * (1.0 - 0.005)


@pytest.mark.parametrize(("std_ratio", "anisotropy"), [(0.3, 1.0), (1.0, 1.0), (1.0, 3.0), (3.0, 1.0)])
def test_the_flat_top_product_matches_the_exact_disk_times_lobe(std_ratio: float, anisotropy: float) -> None:
    """Against a 500² quadrature of disk × Gaussian lobe, centred, k s α = 2 along the lobe's long axis:
    the phasor within the documented centred maximum (0.079, docs/physics_interactions.md §3) and at least
    as close as the Gaussian product."""
    alpha = 0.08
    std = std_ratio * alpha / 2.0
    acceptance_cov = ((std * anisotropy) ** 2, 0.0, std**2)
    grid = ((np.arange(500) + 0.5) / 500 * 2 - 1) * alpha
    x, y = np.meshgrid(grid, grid)
    weight = (x**2 + y**2 <= alpha**2) * np.exp(-0.5 * (x**2 / acceptance_cov[0] + y**2 / acceptance_cov[2]))
    g = 2.0 / alpha
    exact = abs(np.sum(weight * np.exp(1j * g * x)) / np.sum(weight))
    _, cov = product((0.0, 0.0), acceptance_cov)
    _, gaussian_cov = product_components(*SOURCE, (0.0, 0.0), acceptance_cov, False, NUMPY)
    flat_error = abs(math.exp(-0.5 * g * g * cov[0]) - exact)
    gaussian_error = abs(math.exp(-0.5 * g * g * float(gaussian_cov[0])) - exact)
    assert flat_error <= 0.079
    assert flat_error <= gaussian_error + 1e-3
