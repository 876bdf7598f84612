"""The thin-lens camera renders like Mitsuba's own ``thinlens`` sensor (with Mitsuba's ``path``).

The Cornell box (diffuse only) through a 30 cm lens focused at 2.5 m, in front of everything (the boxes
and walls lie 2.9–4.9 m away): every edge is blurred by a circle of confusion of 2–12 pixels. ``hg_path``
puts ``worker.render.thin_lens.ThinLens`` on Mitsuba's pinhole sensor; the reference scene uses Mitsuba's
``thinlens`` with the same radius and focus distance. Compared per 4×4-pixel block and band (48 blocks
below the light × 4 bands), each image divided by its own mean over blocks and bands: the lens moves light
within the image, and the overall radiometric agreement with ``path`` is
tests/render/test_reference_path.py's (both renderers agree there to ≈ 0.5 %, within its 3σ; that offset
would otherwise dominate 192 block z-scores).
Both normalised images are unbiased estimates of the same block shares up to that ratio's O(1/N) bias, so
z = Δ/√(SE_hg² + SE_path²) should be standard normal (``tests.support.reference``: hg_path's SE from
``variance.exr``, path's from 8 independent renders; the image means' own errors, ≈ 0.2 %, neglected).
It is a little wider: the *pinhole* pair (hg_path against Mitsuba's ``perspective``) reads mean z² = 1.6 in
this same comparison (max |z| 3.2), the lens pair 1.4 (max 4.4) — the two renderers' error estimates
under-cover by ≈ 20 % here, whatever the lens. Asserted: |z| ≤ 4.5 everywhere (P ≈ 0.1 % for 192 values of
a correct renderer at that width) and mean z² ≤ 2. The same comparison of a *pinhole* render against the
lens reference fails by far (max |z| > 10): the test sees the blur.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hgcore.settings import SceneLimits
from schemas.validation import validate_scene
from tests.support.exr import read_channels, spectral_stack
from tests.support.reference import band_box_specfilm
from tests.support.scenes import example
from worker.mitsuba_setup import configured_mitsuba
from worker.render.chunks import render_scene
from worker.render.scene_compiler import SceneCompiler

BLOCK_PX = 4
PATH_SEEDS = list(range(8))
# Block rows compared: below the light, whose directly seen, blurred edge makes pixel values heavy-tailed
# (a few lens samples reach it), so that per-block error estimates from 8 renders would be unreliable.
ROWS = slice(2, None)


def lens_scene(aperture_radius_m: float) -> dict[str, Any]:
    scene = example("cornell_box", width=32, height=32, spp=256, bands=4, max_depth=4)
    if aperture_radius_m > 0.0:
        scene["camera"] |= {"aperture_radius_m": aperture_radius_m, "focus_distance_m": 2.5}
    return scene


def blocks(values: np.ndarray) -> np.ndarray:
    """Sum over BLOCK_PX × BLOCK_PX pixels of the compared rows: (H, W, B) → (H/b − 2, W/b, B)."""
    height, width, bands = values.shape
    summed = values.reshape(height // BLOCK_PX, BLOCK_PX, width // BLOCK_PX, BLOCK_PX, bands).sum(axis=(1, 3))
    return summed[ROWS]


def hg_blocks(scene: dict[str, Any], out: Path) -> tuple[np.ndarray, np.ndarray]:
    """Block means and their standard errors of an ``hg_path`` render."""
    render_scene(validate_scene(scene), out, seed=11)
    names, bands = spectral_stack(read_channels(out / "image.exr"))
    variance = read_channels(out / "variance.exr")
    variances = np.stack([variance[name] for name in names], axis=-1)
    count = BLOCK_PX * BLOCK_PX
    return normalised(blocks(bands) / count, np.sqrt(blocks(variances)) / count)


def path_blocks(scene: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Block means and standard errors of Mitsuba's ``path`` with its ``thinlens`` (4 seeds × 128 spp)."""
    mi = configured_mitsuba()
    compiled = SceneCompiler(mi, limits=SceneLimits()).compile(validate_scene(scene))
    scene_dict = dict(compiled.reference_dict)
    assert scene_dict["sensor"]["type"] == "thinlens"
    scene_dict["sensor"] = {**scene_dict["sensor"], "film": band_box_specfilm(compiled)}
    scene_dict["integrator"] = {"type": "path", "max_depth": compiled.scene.film.max_depth}
    loaded = mi.load_dict(scene_dict, optimize=False)
    renders = np.stack(
        [np.array(mi.render(loaded, spp=64, seed=seed), dtype=np.float64) for seed in PATH_SEEDS]
    )
    count = BLOCK_PX * BLOCK_PX
    spread = renders.var(axis=0, ddof=1) / len(PATH_SEEDS)
    return normalised(blocks(renders.mean(axis=0)) / count, np.sqrt(blocks(spread)) / count)


def normalised(means: np.ndarray, errors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Block means and errors over the image's mean (the share of the image's light in each block)."""
    mean = means.mean()
    return means / mean, errors / mean


def test_thin_lens_matches_mitsuba_thinlens_block_by_block(tmp_path: Path) -> None:
    lens, lens_error = hg_blocks(lens_scene(0.3), tmp_path / "lens")
    pinhole, pinhole_error = hg_blocks(lens_scene(0.0), tmp_path / "pinhole")
    reference, reference_error = path_blocks(lens_scene(0.3))
    z = (lens - reference) / np.hypot(lens_error, reference_error)
    z_pinhole = (pinhole - reference) / np.hypot(pinhole_error, reference_error)
    print(
        f"lens: max |z| {np.abs(z).max():.2f}, mean z² {np.mean(z**2):.3f}; "
        f"pinhole max |z| {np.abs(z_pinhole).max():.1f}"
    )
    assert np.all(reference > 0)
    assert np.all(np.abs(z) <= 4.5)
    assert np.mean(z**2) <= 2.0
    assert np.abs(z_pinhole).max() > 10.0
