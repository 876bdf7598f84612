"""``rlt`` (radiometric baseline) against ``hg_path`` (PLT) where the physics says they agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.artifacts.layout import VARIANCE_EXR
from tests.render.scenes import example
from worker.render.api import render_scene


def render_bands(scene: dict, out: Path, integrator: str) -> tuple[np.ndarray, np.ndarray]:
    render_scene(scene, out, integrator=integrator)
    image, variance = read_exr(out / "image.exr"), read_exr(out / VARIANCE_EXR)
    return image.stack(image.band_names()), variance.stack(image.band_names())


@pytest.mark.slow
def test_rlt_agrees_with_hg_path_under_a_point_like_source(tmp_path: Path) -> None:
    """A 0.1 mm sphere 0.59 m from the coated shell: its coherence length 2r/(ka) ≈ 1 mm dwarfs the film's
    µm shear (μ = 1 to 1e-6) and the sampled points lie within 0.2 mrad of its centre, so a coherent plane
    wave per sample (rlt) and the shape-matrix transport (hg_path) give the same film reflectance. Same
    seed, same paths: each band's image mean agrees within 4 standard errors (from variance.exr)."""
    scene = example("fig7_thin_film_sphere_light", width=32, height=32, spp=16)
    scene["emitters"][0]["radius_m"] = 1e-4
    plt, plt_variance = render_bands(scene, tmp_path / "plt", "hg_path")
    rlt, _ = render_bands(scene, tmp_path / "rlt", "rlt")
    lit = plt.sum(axis=-1) > 0
    difference = (rlt - plt)[lit].sum(axis=0)
    standard_error = np.sqrt(2.0 * plt_variance[lit].sum(axis=0))
    assert plt[lit].sum() > 0
    assert np.all(np.abs(difference) <= 4.0 * standard_error + 1e-6 * plt[lit].sum(axis=0))
