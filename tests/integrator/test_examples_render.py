"""Every example scene in schemas/examples renders (tiny) to finite, lit images with diagnostics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from worker.render.api import render_scene

EXAMPLES = sorted((Path(__file__).parents[2] / "schemas" / "examples").glob("*.json"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_renders(path: Path, tmp_path: Path) -> None:
    scene = json.loads(path.read_text())
    scene["film"] = {**scene.get("film", {}), "width": 16, "height": 16}
    summary = render_scene(scene, tmp_path, spp=2)
    image = oiio.ImageInput.open(str(tmp_path / "image.exr"))
    names = list(image.spec().channelnames)
    pixels = np.asarray(image.read_image("float"))
    image.close()
    assert np.all(np.isfinite(pixels))
    spectral = [i for i, name in enumerate(names) if name.startswith("S0.")]
    assert pixels[..., spectral].mean() > 0.0  # some light reaches the camera
    assert summary["coherence"]["covered_pixels"] > 0
    l1 = pixels[..., names.index("coherence.l1_um")]
    l2 = pixels[..., names.index("coherence.l2_um")]
    covered = pixels[..., names.index("coherence.weight")] > 0
    assert np.all(l1[covered] >= l2[covered] * (1 - 1e-5))  # ℓ₁ ≥ ℓ₂ by definition
