"""Natural light: an environment (a constant dome or a lat-long HDR image) and a sun of finite angular size.

Checked against closed forms and independent renderers:
* a constant dome of radiance L on a diffuse sphere: every point of a convex body sees the whole
  hemisphere, so its radiance is ρ·L (a furnace); the background is L;
* its coherence (overcast sky): van Cittert–Zernike over the arrival directions, weighted by the light they
  bring (L·cos θ for a Lambertian receiver), gives Cov(ω⊥) = ½E[sin²θ] = ¼ per axis, M = k²/4, ℓ = 2/k
  (0.175 µm at 550 nm): a coherence of the order of the wavelength;
* an HDR image: the radiance of a diffuse sphere under it agrees with Mitsuba's ``path`` on the same
  ``envmap`` (whose sampling hg_path shares);
* a sun of angular radius α: van Cittert–Zernike over a uniform disk of directions, computed here by
  quadrature over the cone, gives ℓ = 2/(k sin α) (37.85 µm for 0.53° at 550 nm); a diffuse floor in it has
  the radiance ρ/π·E_λ·cos θ of its irradiance.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hgcore.artifacts.layout import K_REFERENCE_PER_M
from hgcore.settings import SceneLimits
from schemas.photometry import emitter_radiance_scale, evaluate_spectrum
from schemas.validation import validate_scene
from tests.support.exr import read_channels, spectral_stack
from tests.support.images import sky_image, write_image
from tests.support.reference import image_mean_with_error, path_band_means
from tests.support.sums import assert_bitwise_equal, sums_of
from worker.mitsuba_setup import configured_mitsuba
from worker.render.chunks import render_scene
from worker.render.renderer import Renderer
from worker.render.scene_compiler import SceneCompiler

BANDS = 8
SPHERE_RADIUS_M, CAMERA_DISTANCE_M, FOV_DEG = 0.5, 3.0, 30.0


def sphere_scene(emitter: dict[str, Any], *, size_px: int = 32, spp: int = 64) -> dict[str, Any]:
    return {
        "schema": "hgrender/scene/v1",
        "name": "diffuse sphere in natural light",
        "camera": {"origin_m": [0, 0, CAMERA_DISTANCE_M], "target_m": [0, 0, 0], "fov_deg": FOV_DEG},
        "film": {"width": size_px, "height": size_px, "spp": spp, "bands": BANDS, "max_depth": 4},
        "materials": {"grey": {"type": "diffuse", "reflectance": 0.5}},
        "shapes": [
            {"type": "sphere", "material": "grey", "center_m": [0, 0, 0], "radius_m": SPHERE_RADIUS_M}
        ],
        "emitters": [emitter],
    }


def sphere_pixels(size_px: int) -> tuple[np.ndarray, np.ndarray]:
    """(pixels whose whole footprint is on the sphere, pixels whose footprint misses it), pinhole camera."""
    half = math.tan(math.radians(FOV_DEG) / 2.0)
    centres = ((np.arange(size_px) + 0.5) / size_px * 2.0 - 1.0) * half
    x, y = np.meshgrid(centres, centres)
    angle = np.arctan(np.hypot(x, y))
    silhouette = math.asin(SPHERE_RADIUS_M / CAMERA_DISTANCE_M)
    pixel = 2.0 * half / size_px
    return angle < silhouette - pixel, angle > silhouette + pixel


@pytest.fixture(scope="module")
def dome(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    """A grey sphere under a constant dome L = 1.5 (every wavelength), 32² px, 64 spp."""
    out = tmp_path_factory.mktemp("dome")
    emitter = {"type": "environment", "spectrum": {"type": "constant", "value": 1.0}, "radiance_scale": 1.5}
    render_scene(validate_scene(sphere_scene(emitter)), out)
    channels = read_channels(out / "image.exr")
    variance = read_channels(out / "variance.exr")
    names, bands = spectral_stack(channels)
    return {
        "bands": bands,
        "variance": np.stack([variance[name] for name in names], axis=-1),
        **{name: channels[f"coherence.{name}"] for name in ("Mxx", "Mxy", "Myy", "weight")},
    }


def test_a_constant_dome_lights_a_diffuse_sphere_with_rho_times_l(dome: dict[str, np.ndarray]) -> None:
    on_sphere, background = sphere_pixels(32)
    means = image_mean_with_error(dome["bands"][on_sphere][:, None], dome["variance"][on_sphere][:, None])
    assert np.all(means.standard_error < 0.01 * 0.75)
    assert np.all(np.abs(means.mean - 0.5 * 1.5) <= 4.0 * means.standard_error), means
    # The dome seen directly: each sample's four wavelengths fall in 4 of the 8 bands, so a pixel's bands
    # scatter around L, and their mean is L exactly.
    np.testing.assert_allclose(dome["bands"][background].mean(axis=-1), 1.5, rtol=1e-6)


def test_an_overcast_sky_gives_a_coherence_of_the_order_of_the_wavelength(
    dome: dict[str, np.ndarray],
) -> None:
    # The pixels' M (the VCZ estimate from the arrival directions of each pixel's paths, docs/physics.md §9)
    # averaged over the sphere: unbiased for M (per-pixel eigenvalues are biased apart, their mean is not).
    on_sphere, _ = sphere_pixels(32)
    assert np.all(dome["weight"][on_sphere] > 0)
    expected = K_REFERENCE_PER_M**2 / 4.0  # Cov(ω⊥) = 1/4 per axis: ℓ = 2/k = 0.175 µm
    for key in ("Mxx", "Myy"):
        values = dome[key][on_sphere]
        error = values.std(ddof=1) / math.sqrt(values.size)
        assert abs(values.mean() - expected) <= 4.0 * error + 0.01 * expected, (key, values.mean(), expected)
    xy = dome["Mxy"][on_sphere]
    assert abs(xy.mean()) <= 4.0 * xy.std(ddof=1) / math.sqrt(xy.size) + 0.01 * expected
    length_um = 1e6 / math.sqrt(0.5 * (dome["Mxx"][on_sphere].mean() + dome["Myy"][on_sphere].mean()))
    assert 0.17 < length_um < 0.18  # 2/k = λ/π at 550 nm


def sky() -> np.ndarray:
    """A 64 × 32 sky whose patch of 4 × 2 texels 30° above the horizon is 60 times brighter than the sky."""
    return sky_image(64, 32, (slice(9, 11), slice(20, 24)), (60.0, 45.0, 30.0))


def test_an_hdr_environment_agrees_with_mitsubas_path_on_a_diffuse_sphere(tmp_path: Path) -> None:
    # Both estimate the same per-band image means; |Δ| ≤ 3·√(SE_hg² + SE_path²) per band (as
    # tests/render/test_reference_path.py: the chance that one of 8 bands lies beyond 3σ is ≈ 2 %).
    write_image(tmp_path / "sky.exr", sky())
    emitter = {"type": "environment", "path": "sky.exr", "radiance_scale": 0.8,
               "transform": {"rotate_axis": [0, 1, 0], "rotate_deg": 35.0}}  # fmt: skip
    scene = sphere_scene(emitter, size_px=24, spp=256)
    render_scene(validate_scene(scene), tmp_path / "out", bundle_dir=tmp_path)
    names, bands = spectral_stack(read_channels(tmp_path / "out" / "image.exr"))
    variance = read_channels(tmp_path / "out" / "variance.exr")
    ours = image_mean_with_error(bands, np.stack([variance[name] for name in names], axis=-1))
    mi = configured_mitsuba()
    compiled = SceneCompiler(mi, tmp_path, limits=SceneLimits()).compile(validate_scene(scene))
    reference = path_band_means(mi, compiled, 64, list(range(8)))
    combined = np.sqrt(ours.standard_error**2 + reference.standard_error**2)
    assert np.all(ours.standard_error <= 0.03 * ours.mean)
    z = (ours.mean - reference.mean) / combined
    assert np.all(np.abs(z) <= 3.0), z


def vcz_disk_covariance(half_angle_rad: float, nodes: int = 64) -> float:
    """Cov of ω⊥ along one axis for directions uniform in solid angle within a cone of half-angle α: the
    curvature of van Cittert–Zernike's μ(ξ) = ⟨e^{ik ω⊥·ξ}⟩ at 0, by Gauss–Legendre quadrature in cos θ (the
    azimuthal mean of cos²φ is ½)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    cos_theta = math.cos(half_angle_rad) + (1.0 - math.cos(half_angle_rad)) * (x + 1.0) / 2.0
    weights = w / w.sum()
    return float(np.sum(weights * 0.5 * (1.0 - cos_theta**2)))


def test_the_sun_has_the_coherence_of_a_uniform_disk_and_its_irradiance(tmp_path: Path) -> None:
    sun = {
        "type": "sun",
        "direction": [0.3, 1.0, 0.2],
        "angular_diameter_deg": 0.53,
        "irradiance_w_m2": 800.0,
    }
    scene = {
        "schema": "hgrender/scene/v1",
        "name": "floor in the sun",
        "camera": {"origin_m": [0, 1.0, 2.0], "target_m": [0, 0, 0], "fov_deg": 20.0},
        "film": {"width": 16, "height": 16, "spp": 16, "bands": BANDS, "max_depth": 2},
        "materials": {"grey": {"type": "diffuse", "reflectance": 0.5}},
        "shapes": [
            {
                "type": "rectangle",
                "material": "grey",
                "center_m": [0, 0, 0],
                "normal": [0, 1, 0],
                "up": [0, 0, -1],
                "width_m": 4.0,
                "height_m": 4.0,
            }
        ],
        "emitters": [sun],
    }
    validated = validate_scene(scene)
    render_scene(validated, tmp_path)
    channels = read_channels(tmp_path / "image.exr")
    expected_um = 1e6 / (K_REFERENCE_PER_M * math.sqrt(vcz_disk_covariance(math.radians(0.265))))
    assert abs(expected_um - 37.852) < 0.01
    for key in ("l1_um", "l2_um"):  # the sun's Σ⊥ is exact (no estimate): float32 arithmetic only
        np.testing.assert_allclose(channels[f"coherence.{key}"], expected_um, rtol=1e-4)
    # ρ/π · E_λ · cos θ, E_λ = c·s(λ)·Ω band-averaged (the floor sees all of the sun: NEE weights are
    # constant up to the disk's 0.27° of cos θ, so the error is the wavelengths' sampling within the bands)
    model = validated.emitters[0]
    film = validated.film
    scale = emitter_radiance_scale(model, film.wavelength_min_nm, film.wavelength_max_nm)
    edges = np.linspace(film.wavelength_min_nm, film.wavelength_max_nm, BANDS + 1)
    grid = np.linspace(edges[:-1], edges[1:], 200, axis=1)
    spectral = evaluate_spectrum(model.spectrum, grid.ravel()).reshape(grid.shape).mean(axis=1)
    cos_theta = 1.0 / math.sqrt(0.3**2 + 1.0 + 0.2**2)
    expected = 0.5 / math.pi * scale * spectral * model.solid_angle_sr() * cos_theta
    _, bands = spectral_stack(channels)
    np.testing.assert_allclose(bands.mean(axis=(0, 1)), expected, rtol=0.01)


def test_passes_with_textures_an_environment_and_a_sun_replay_bitwise(tmp_path: Path) -> None:
    # Frozen passes must name every array their kernels read: the texture tables and Mitsuba's envmap.
    write_image(tmp_path / "sky.exr", sky())
    write_image(tmp_path / "tau.exr", np.linspace(0.2, 0.8, 8, dtype=np.float32).reshape(2, 4, 1))
    scene = sphere_scene({"type": "environment", "path": "sky.exr"}, size_px=16, spp=8)
    scene["emitters"].append({"type": "sun", "direction": [0, 1, 1], "irradiance_w_m2": 100.0})
    scene["materials"]["grey"] = {
        "type": "thin_film",
        "film_thickness_um": {"type": "image", "path": "tau.exr"},
        "film_ior": 1.33,
        "substrate": {"conductor": "Ag"},
    }
    renderer = Renderer(
        SceneCompiler(configured_mitsuba(), tmp_path, limits=SceneLimits()).compile(validate_scene(scene))
    )
    frozen = [sums_of(renderer, seed) for seed in (3, 4, 3)]
    assert renderer.frozen_passes, "the scene's passes could not be recorded"
    renderer.frozen_passes = False
    traced = [sums_of(renderer, seed) for seed in (3, 4)]
    assert_bitwise_equal(frozen[0], traced[0])
    assert_bitwise_equal(frozen[1], traced[1])
    assert_bitwise_equal(frozen[2], traced[0])
