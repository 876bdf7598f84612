"""``rlt`` (radiometric baseline) against ``hg_path`` (PLT) where the physics says they agree.

A point-like source here; extended sources through smooth and rough films, at a pinhole and through lenses
whose cone is smaller than, like and larger than the source, in tests/integrator/test_detected_coherence.py
(where ``rlt`` once kept a smooth film's fringes that ``hg_path`` washed out: a pixel sees one direction of
the source through a smooth film, and the two now agree).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.artifacts.layout import VARIANCE_EXR
from schemas import validate_scene
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
