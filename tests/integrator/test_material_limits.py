"""Consistency limits between materials: a rough surface with vanishing roughness is a smooth one.

With RMS height σ_h → 0 the Harvey specular fraction e^{−g}, g = (4πσ_h cos θ/λ)², tends to 1, so a rough
conductor must render like a mirror of the same metal and a rough dielectric like smooth glass. For
σ_h = 1 nm, 1 − e^{−g} < 6·10⁻⁴ at 380 nm — far below the Monte Carlo tolerance used (4 standard errors of
the difference of two independent image means).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from schemas import build, validate_scene
from worker.render.chunks import render_scene

BOX = build.scene(
    "object in a box",
    camera=build.camera([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], fov_deg=40.0),
    film=build.film(24, bands=4, spp=64, max_depth=6),
    materials={"wall": {"type": "diffuse", "reflectance": 0.7}},
    shapes=[
        build.rectangle([0, -1, 0], normal=[0, 1, 0], up=[0, 0, -1], width_m=2, material="wall"),
        build.rectangle([0, 0, -1], normal=[0, 0, 1], up=[0, 1, 0], width_m=2, material="wall"),
        build.sphere([0, -0.4, 0], 0.5, material="object"),
    ],
    emitters=[
        build.rectangle(
            [0, 0.99, 0],
            normal=[0, -1, 0],
            up=[0, 0, 1],
            width_m=0.6,
            spectrum={"type": "d65"},
            radiance_scale=5.0,
        )
    ],
)


def render_bands(material: dict, tmp_path: Path, name: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    scene = copy.deepcopy(BOX)
    scene["materials"]["object"] = material
    render_scene(validate_scene(scene), tmp_path / name, seed=seed)
    image = read_exr(tmp_path / name / "image.exr")
    variance = read_exr(tmp_path / name / "variance.exr")
    bands = image.band_names()
    return image.stack(bands), variance.stack(bands)


@pytest.mark.parametrize(
    ("rough", "smooth"),
    [
        (
            {
                "type": "rough_conductor",
                "conductor": "Au",
                "roughness_rms_um": 0.001,
                "correlation_length_um": 5.0,
            },
            {"type": "mirror", "conductor": "Au"},
        ),
        (
            {"type": "rough_dielectric", "ior": 1.5, "roughness_rms_um": 0.001, "correlation_length_um": 5.0},
            {"type": "dielectric", "ior": 1.5},
        ),
    ],
    ids=["conductor", "dielectric"],
)
def test_vanishing_roughness_matches_the_smooth_material(rough: dict, smooth: dict, tmp_path: Path) -> None:
    rough_bands, rough_variance = render_bands(rough, tmp_path, "rough", seed=1)
    smooth_bands, smooth_variance = render_bands(smooth, tmp_path, "smooth", seed=2)
    pixel_count = rough_bands.shape[0] * rough_bands.shape[1]
    for band in range(rough_bands.shape[-1]):
        difference = rough_bands[..., band].mean() - smooth_bands[..., band].mean()
        standard_error = (
            np.sqrt(rough_variance[..., band].sum() + smooth_variance[..., band].sum()) / pixel_count
        )
        assert abs(difference) <= 4.0 * standard_error, (band, difference, standard_error)
    assert smooth_bands.mean() > 0


def test_rough_dielectric_transmits_and_scatters(tmp_path: Path) -> None:
    rough = {"type": "rough_dielectric", "ior": "bk7", "roughness_rms_um": 0.3, "correlation_length_um": 2.0}
    bands, _ = render_bands(rough, tmp_path, "frosted", seed=3)
    assert np.all(np.isfinite(bands))
    assert bands.mean() > 0
