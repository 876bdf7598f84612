"""``rlt`` (radiometric baseline) against ``hg_path`` (PLT) where the physics says they agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.artifacts.layout import VARIANCE_EXR
from schemas import validate_scene
from tests.render.scenes import COATED_PLANE, constant_spectrum
from tests.support.scenes import example
from worker.render.chunks import render_scene


def render_bands(scene: dict, out: Path, integrator: str) -> tuple[np.ndarray, np.ndarray]:
    render_scene(validate_scene(scene), out, integrator=integrator)
    image, variance = read_exr(out / "image.exr"), read_exr(out / VARIANCE_EXR)
    return image.stack(image.band_names()), variance.stack(image.band_names())


@pytest.mark.slow
def test_rlt_agrees_with_hg_path_under_a_point_like_source(tmp_path: Path) -> None:
    """A 0.5 mm sphere 0.3 m from the coated shell: its coherence length 2r/(ka) ≈ 0.1 mm dwarfs the film's
    sub-µm shear (μ = 1 to 1e-5) and the sampled points lie within 2 mrad of its centre, so a coherent
    plane wave per sample (rlt) and the shape-matrix transport (hg_path) give the same film reflectance.
    Same seed, same paths: each band's image mean agrees within 4 standard errors (from variance.exr).
    Every pixel must be finite: a sphere of angular radius a/d below √(2⁻²⁴) ≈ 2.4e-4 (the 0.1 mm one
    this test used) makes Mitsuba's float32 cone sampling degenerate (cos α = 1, pdf = ∞) and hg_path's
    MIS weight ∞/∞ = NaN on every diffuse pixel (a renderer limit: such a sphere is a point light)."""
    scene = example("fig7_thin_film_sphere_light", width=32, height=32, spp=16)
    scene["emitters"][0]["radius_m"] = 5e-4
    plt, plt_variance = render_bands(scene, tmp_path / "plt", "hg_path")
    rlt, _ = render_bands(scene, tmp_path / "rlt", "rlt")
    assert np.all(np.isfinite(plt)) and np.all(np.isfinite(rlt))
    lit = plt.sum(axis=-1) > 0
    difference = (rlt - plt)[lit].sum(axis=0)
    standard_error = np.sqrt(2.0 * plt_variance[lit].sum(axis=0))
    assert plt[lit].sum() > 0
    assert np.all(np.abs(difference) <= 4.0 * standard_error + 1e-6 * plt[lit].sum(axis=0))


def coated_plane_under_a_large_source(seed: int) -> dict:
    """A smooth coated plane (1.23 µm, n_f = 1.5, on a dielectric n_s = 2.25 so that |r_01| ≈ |r_12| ≈ 0.2
    and the coherent fringes span R ≈ 0…0.15; σ = 5 nm: specular) seen at θ = 59° from its normal through
    a 3° field (incidence varies by ±1.5°, the fringe phase by ±0.3 rad), with a constant-spectrum sphere
    of radius 0.2 m centred on the mirror image of the camera, 0.58 m from the plane's centre: every pixel
    sees the sphere by specular reflection."""
    coating = {"type": "thin_film", "film_thickness_um": 1.23, "film_ior": 1.5, "substrate": {"ior": 2.25}}
    return {
        "schema": "hgrender/scene/v1",
        "name": "coated plane, extended source",
        "camera": {
            "type": "perspective",
            "origin_m": [-0.5, 0.0, 0.3],
            "target_m": [0.0, 0.0, 0.0],
            "fov_deg": 3,
        },
        "film": {"width": 24, "height": 24, "bands": 16, "spp": 32, "seed": seed},
        "materials": {"coating": {**coating, "roughness_rms_um": 0.005}},
        "shapes": [COATED_PLANE],
        "emitters": [
            {"type": "sphere", "center_m": [0.5, 0.0, 0.3], "radius_m": 0.2, **constant_spectrum(50.0)}
        ],
    }


def fringe_power(bands: np.ndarray) -> float:
    """The relative spectral variance var_b(S_b)/mean_b(S_b)² of the image's summed spectrum S_b (source
    flat, substrate and film non-dispersive: only the film's fringes vary with λ, plus noise)."""
    spectrum = bands.sum(axis=(0, 1))
    return float(spectrum.var() / spectrum.mean() ** 2)


@pytest.mark.slow
def test_rlt_keeps_the_film_fringes_that_partial_coherence_washes_out(tmp_path: Path) -> None:
    """Where theory says they disagree. A smooth film reflects each pixel's light specularly, from one
    point of the source, at one angle θ. RLT evaluates that plane wave coherently: R = R_inc + 2 Σ_d X_d(θ)
    (V ≡ 1). PLT evaluates the field's partial coherence at the film's shear s = τ sin θ = 1.05 µm:
    R = R_inc + 2 Σ_d V_d X_d(θ), and the sphere (radius a at r = 0.58 m) has ℓ = 2r/(ka) = 0.51 µm, so
    s/ℓ ≈ 2 and V_1 < 0.2 (V_d ≤ V_1). Same paths, same θ: PLT's fringe terms are RLT's scaled by V_d,
    hence its relative spectral variance is ≈ V_1² ≈ 2 % of RLT's fringe part — the expected direction:
    RLT's spectrum keeps the fringes, PLT's is nearly flat. Measured over 4 seeds: the difference
    P_RLT − P_PLT must exceed 4 standard errors of its seed-to-seed scatter (the Monte Carlo error:
    wavelength and reflect/transmit sampling), and P_PLT must be below a quarter of P_RLT (V_1² < 0.04,
    with room for PLT's noise floor, which the 4-seed scatter bounds)."""
    plt_power, rlt_power = [], []
    for seed in range(4):
        scene = coated_plane_under_a_large_source(seed)
        plt, _ = render_bands(scene, tmp_path / f"plt{seed}", "hg_path")
        rlt, _ = render_bands(scene, tmp_path / f"rlt{seed}", "rlt")
        assert (plt.sum(axis=-1) > 0).mean() > 0.9
        plt_power.append(fringe_power(plt))
        rlt_power.append(fringe_power(rlt))
    differences = np.subtract(rlt_power, plt_power)
    standard_error = float(np.std(differences, ddof=1) / np.sqrt(len(differences)))
    assert float(np.mean(differences)) > 4.0 * standard_error
    assert float(np.mean(plt_power)) < 0.25 * float(np.mean(rlt_power))
