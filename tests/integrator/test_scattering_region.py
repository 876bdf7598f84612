"""Consequences of the scattering-region model (docs/physics.md §7) in rendered diagnostics.

A floor lit only by a diffuse wall (the one-sided emitter faces the wall, the floor's visible part lies
behind the emitter's plane) receives light whose coherence is that of the wall's scattering regions: a
uniform disk of radius a, so M = (k/r)²·a²/4·(I − n⊥n⊥ᵀ) and ℓ ∝ r/(k·a). The region's size does not
affect path sampling, so renders with the same seed trace identical paths and the diagnostics must scale
exactly: ℓ₁, ℓ₂ ∝ 1/a, anisotropy and r unchanged (float32 rounding only).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from hgcore.artifacts.exr import read_exr
from schemas import build, validate_scene
from worker.render.chunks import render_scene

SCENE = build.scene(
    "floor lit by a wall",
    camera=build.camera([1.5, 2.0, 0.0], [1.5, 0.0, 0.0], up=[0, 0, -1], fov_deg=30.0),
    film=build.film(16, bands=4, spp=16, max_depth=3),
    materials={
        "floor": {"type": "diffuse", "reflectance": 0.5},
        "wall": {"type": "diffuse", "reflectance": 0.8, "scattering_region_radius_m": 0.001},
    },
    shapes=[
        build.rectangle([1.0, 0.0, 0.0], normal=[0, 1, 0], up=[0, 0, -1], width_m=4.0, material="floor"),
        build.rectangle([-0.5, 1.0, 0.0], normal=[1, 0, 0], up=[0, 1, 0], width_m=2.0, material="wall"),
    ],
    emitters=[
        build.rectangle(
            [0.5, 1.0, 0.0],
            normal=[-1, 0, 0],
            up=[0, 1, 0],
            width_m=0.3,
            spectrum={"type": "d65"},
            radiance_scale=10.0,
        )
    ],
)


def diagnostics(radius_m: float, tmp_path: Path) -> dict[str, np.ndarray]:
    scene = copy.deepcopy(SCENE)
    scene["materials"]["wall"]["scattering_region_radius_m"] = radius_m
    render_scene(validate_scene(scene), tmp_path / f"a{radius_m}", seed=7)
    channels = read_exr(tmp_path / f"a{radius_m}" / "image.exr").channels
    return {name: values for name, values in channels.items() if name.startswith("coherence.")}


def test_coherence_lengths_scale_inversely_with_the_region_radius(tmp_path: Path) -> None:
    small = diagnostics(0.001, tmp_path)
    large = diagnostics(0.002, tmp_path)
    covered = small["coherence.weight"] > 0
    assert covered.sum() >= 100
    np.testing.assert_allclose(large["coherence.weight"], small["coherence.weight"], rtol=1e-6)
    np.testing.assert_allclose(large["coherence.r_m"][covered], small["coherence.r_m"][covered], rtol=1e-5)
    np.testing.assert_allclose(
        small["coherence.l1_um"][covered] / large["coherence.l1_um"][covered], 2.0, rtol=1e-4
    )
    np.testing.assert_allclose(
        small["coherence.l2_um"][covered] / large["coherence.l2_um"][covered], 2.0, rtol=1e-4
    )
    np.testing.assert_allclose(
        large["coherence.anisotropy"][covered], small["coherence.anisotropy"][covered], rtol=1e-4
    )
    # ℓ₂ (the unforeshortened axis) of one path is r/(k·a/2). Pixels average M ∝ 1/r² while r_m averages r
    # (same luminance weights): by the power-mean inequality (E[r⁻²])^{−1/2} ≤ E[r], the ratio is ≤ 1,
    # and ≥ r_min/r_max over a pixel's paths (> 0.3 here: the wall is 1–3 m from the visible floor).
    r = small["coherence.r_m"][covered]
    assert np.all((r > 0.5) & (r < 4.0))
    l2_single_path = r / (2 * np.pi / 550e-9 * 0.001 / 2) * 1e6
    ratio = small["coherence.l2_um"][covered] / l2_single_path
    assert np.all(ratio <= 1.0 + 1e-4), ratio.max()
    assert np.all(ratio > 0.3), ratio.min()
