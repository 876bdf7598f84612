"""Sphere lights much smaller than their distance: finite, and the same light as a larger one of equal power.

In float32, Mitsuba's sphere cone sampling forms 1 − cos α with cancellation: its pdf is 3 % high for a 1 mm
sphere at 0.6 m and infinite below a/d ≈ 2.4e-4 (cos α rounds to 1), where the emitter weight is 0 and the
balance heuristic ∞/∞ is NaN (a 0.1 mm sphere left 611 of 1024 pixels NaN). ``hg_path`` uses the stable
solid angle Ω = 2π sin²α/(1 + cos α) (``emitters.sphere_solid_angle``) for both strategies.

The floor is lit directly (max_depth 2) by a sphere 0.6 m above it that the camera does not see. A
uniformly radiating sphere wholly above a receiver's horizon gives it the irradiance of a point source of
intensity P/4π (the shell theorem for Lambertian spheres), so spheres of equal power must agree; the
tolerance is 4 standard errors of the mean per-pixel difference (the renders share the camera and the
seed, so the difference's scatter is their noise) plus (a/h)² relative for the larger sphere: Mitsuba
draws directions from its float32 cone, not exactly uniformly over the silhouette, and the integrand
cos θ/r² varies across the cone by O(α²) (first-order variations cancel by symmetry), plus 1e-6 for
float32 accumulation.
A third render at 3 mm checks the 1 mm one in the range where Mitsuba's own pdf is finite but biased.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from schemas import build, validate_scene
from worker.render.chunks import render_scene

HEIGHT_M = 0.6
POWER_W = 1.0


def scene(radius_m: float) -> dict:
    return build.scene(
        f"sphere light of radius {radius_m} m",
        camera=build.camera([0.0, -0.4, 0.5], [0.0, 0.0, 0.0], up=[0.0, 0.0, 1.0], fov_deg=30.0),
        film=build.film(16, bands=4, spp=64, max_depth=2),
        materials={"floor": {"type": "diffuse", "reflectance": 0.5}},
        shapes=[
            build.rectangle(
                [0.0, 0.0, 0.0], normal=[0.0, 0.0, 1.0], up=[0.0, 1.0, 0.0], width_m=2.0, material="floor"
            )
        ],
        emitters=[
            build.sphere(
                [0.1, 0.1, HEIGHT_M], radius_m, spectrum={"type": "constant", "value": 1.0}, power_w=POWER_W
            )
        ],
    )


def floor_radiance(radius_m: float, out_dir: Path) -> np.ndarray:
    render_scene(validate_scene(scene(radius_m)), out_dir, seed=5)
    image = read_exr(out_dir / "image.exr").channels
    bands = sorted(name for name in image if name.startswith("S0."))
    return np.stack([image[name] for name in bands]).astype(float)


@pytest.fixture(scope="module")
def renders(tmp_path_factory: pytest.TempPathFactory) -> dict[float, np.ndarray]:
    return {
        radius: floor_radiance(radius, tmp_path_factory.mktemp(f"r{radius}")) for radius in (1e-4, 1e-3, 3e-3)
    }


def test_a_tenth_of_a_millimetre_sphere_renders_finite_and_lit(renders: dict[float, np.ndarray]) -> None:
    tiny = renders[1e-4]
    assert np.isfinite(tiny).all(), f"{np.count_nonzero(~np.isfinite(tiny))} non-finite values"
    assert (tiny.mean(axis=0) > 0).all(), "every pixel sees the lit floor"


@pytest.mark.parametrize(("small", "large"), [(1e-4, 1e-3), (1e-3, 3e-3)])
def test_spheres_of_equal_power_light_the_floor_alike(
    renders: dict[float, np.ndarray], small: float, large: float
) -> None:
    a, b = renders[small].mean(axis=0).ravel(), renders[large].mean(axis=0).ravel()
    difference = a - b
    standard_error = float(np.std(difference, ddof=1) / math.sqrt(difference.size))
    print(
        f"{small} m vs {large} m: {a.mean():.6g} vs {b.mean():.6g}, SE of the difference {standard_error:.3g}"
    )
    size_term = (large / HEIGHT_M) ** 2 + 1e-6
    assert abs(difference.mean()) <= 4.0 * standard_error + size_term * b.mean(), (a.mean(), b.mean())
