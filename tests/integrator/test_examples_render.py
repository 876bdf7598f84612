"""Every example scene in schemas/examples renders (tiny) to finite, lit images with diagnostics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from schemas import validate_scene
from tests.support.scenes import example
from worker.render.chunks import render_scene

EXAMPLES = sorted((Path(__file__).parents[2] / "schemas" / "examples").glob("*.json"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_renders(path: Path, tmp_path: Path) -> None:
    scene = example(path.stem, width=16, height=16)
    summary = render_scene(validate_scene(scene), tmp_path, spp=2)
    image = read_exr(tmp_path / "image.exr")
    assert np.all(np.isfinite(image.stack()))
    assert image.stack(image.band_names()).mean() > 0.0  # some light reaches the camera
    assert summary["coherence"]["covered_pixels"] > 0
    l1 = image.channels["coherence.l1_um"]
    l2 = image.channels["coherence.l2_um"]
    covered = image.channels["coherence.weight"] > 0
    assert np.all(l1[covered] >= l2[covered] * (1 - 1e-5))  # ℓ₁ ≥ ℓ₂ by definition
