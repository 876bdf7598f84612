"""Determinism, chunk split/merge and the spectral EXR contract of the BRIEF."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from schemas import validate_scene
from tests.integrator.scenes import plane_under_source
from worker.render.chunks import plan_chunks, render_scene

SPHERE = {
    "type": "sphere",
    "center_m": [0.0, 0.3, 1.0],
    "radius_m": 0.05,
    "spectrum": {"type": "blackbody", "temperature_k": 4000.0},
    "power_w": 50.0,
}


def read_exr_stack(path: Path) -> tuple[list[str], np.ndarray, dict[str, str]]:
    """Channel names in file order, all pixels (H, W, C) and the header attributes."""
    image = read_exr(path)
    return list(image.channels), image.stack(), image.attributes


@pytest.fixture(scope="module")
def scene() -> dict:
    return plane_under_source(SPHERE, size_px=16, spp=8)


def test_plan_chunks_partitions_spp_with_distinct_seeds() -> None:
    plan = plan_chunks(10, 4, 7)
    assert [chunk.spp for chunk in plan] == [3, 3, 2, 2]
    assert len({chunk.seed for chunk in plan}) == 4
    assert plan_chunks(3, 8, 0) == plan_chunks(3, 3, 0)  # never an empty chunk
    with pytest.raises(ValueError, match="spp"):
        plan_chunks(0, 1, 0)


def test_same_seed_is_bitwise_identical_and_other_seed_differs(scene: dict, tmp_path: Path) -> None:
    render_scene(validate_scene(scene), tmp_path / "a", seed=3)
    render_scene(validate_scene(scene), tmp_path / "b", seed=3)
    render_scene(validate_scene(scene), tmp_path / "c", seed=4)
    _, a, _ = read_exr_stack(tmp_path / "a" / "image.exr")
    _, b, _ = read_exr_stack(tmp_path / "b" / "image.exr")
    _, c, _ = read_exr_stack(tmp_path / "c" / "image.exr")
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_split_render_matches_unsplit_in_sample_count_and_expectation(scene: dict, tmp_path: Path) -> None:
    whole = render_scene(validate_scene(scene), tmp_path / "whole", spp=16, seed=1)
    split = render_scene(validate_scene(scene), tmp_path / "split", spp=16, seed=1, chunks=4)
    assert whole["spp"] == split["spp"] == 16
    names, whole_pixels, _ = read_exr_stack(tmp_path / "whole" / "image.exr")
    _, split_pixels, _ = read_exr_stack(tmp_path / "split" / "image.exr")
    _, variance, _ = read_exr_stack(tmp_path / "whole" / "variance.exr")
    bands = [i for i, name in enumerate(names) if name.startswith("S0.")]
    # Image means of two independent estimates: their difference has variance 2·Σ var(pixel mean)/N².
    pixel_count = whole_pixels.shape[0] * whole_pixels.shape[1]
    for slot, channel in enumerate(bands):
        difference = whole_pixels[..., channel].mean() - split_pixels[..., channel].mean()
        standard_error = np.sqrt(2.0 * variance[..., slot].sum()) / pixel_count
        assert abs(difference) <= 4.0 * standard_error + 1e-9, (names[channel], difference, standard_error)


def test_exr_channels_and_attributes_follow_the_contract(scene: dict, tmp_path: Path) -> None:
    summary = render_scene(validate_scene(scene), tmp_path, spp=4)
    names, pixels, attributes = read_exr_stack(tmp_path / "image.exr")
    spectral = [name for name in names if name.startswith("S0.")]
    assert len(spectral) == 8
    assert all(re.fullmatch(r"S0\.\d+,\d{6}nm", name) for name in spectral)
    assert spectral[0] == "S0.405,000000nm"  # 8 bands over 380–780 nm: centres 405, 455, …
    assert attributes["spectralLayoutVersion"] == "1.0"
    assert attributes["emissiveUnits"] == "W.m^-2.sr^-1"
    for name in (
        "R",
        "G",
        "B",
        "depth",
        "normal.X",
        "normal.Y",
        "normal.Z",
        "albedo.R",
        "albedo.G",
        "albedo.B",
    ):
        assert name in names
    for name in ("l1_um", "l2_um", "angle", "anisotropy", "area_um2", "r_m", "Mxx", "Mxy", "Myy"):
        assert f"coherence.{name}" in names
    assert np.all(np.isfinite(pixels))
    depth = pixels[..., names.index("depth")]
    # depth is the ray distance to the first hit: the plane 3 m below the camera at the image centre.
    assert depth[8, 8] == pytest.approx(3.0, rel=0.01)
    normal_z = pixels[..., names.index("normal.Z")]
    assert np.median(np.abs(normal_z)) == pytest.approx(1.0, abs=1e-3)
    albedo = pixels[..., names.index("albedo.G")]
    assert np.median(albedo) == pytest.approx(0.8, abs=0.05)  # grey 0.8 under the equal-energy estimator
    stored = json.loads((tmp_path / "summary.json").read_text())
    assert stored["spp"] == summary["spp"] == 4
    assert (tmp_path / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*tmp"))  # atomic writes leave no temporaries


# A 1 m square light beside the view, facing the plane: every pixel's samples vary alike (where the direct
# view of a small light gives a few pixels all the variance, too heavy-tailed for a few seeds).
SIDE_LIGHT = {
    "type": "rectangle",
    "center_m": [1.5, 0.0, 1.0],
    "normal": [-0.83205, 0.0, -0.5547],
    "up": [0.0, 1.0, 0.0],
    "width_m": 1.0,
    "height_m": 1.0,
    "spectrum": {"type": "blackbody", "temperature_k": 4000.0},
    "power_w": 50.0,
}


def test_variance_exr_luminance_is_the_variance_of_image_exr_luminance(tmp_path: Path) -> None:
    """variance.exr's Y is the variance of the pixel mean of image.exr's luminance, in its units: over
    independent renders (seeds) the scatter s² of each pixel's Y (Rec. 709 weights of image.exr's linear
    sRGB) has the mean v̄ that variance.exr reports, times N/(N−1) (its σ̂² is the 1/N sample variance,
    docs/regression.md). The ratio R = Σs²/Σv̄ over the P independent pixels is
    1 within 4 standard errors, SE = std(s² − R v̄)/(√P mean v̄) (delta method; measured 1.04 ± 0.04).
    Issue 26: Y was 106.857² × too large (∫ȳ dλ missing), R ≈ 1e-4."""
    scene = plane_under_source(SIDE_LIGHT, size_px=16, spp=8)
    luminances, reported = [], []
    for seed in range(1, 9):
        render_scene(validate_scene(scene), tmp_path / str(seed), seed=seed)
        image = read_exr(tmp_path / str(seed) / "image.exr").channels
        luminances.append(0.2126 * image["R"] + 0.7152 * image["G"] + 0.0722 * image["B"])
        reported.append(read_exr(tmp_path / str(seed) / "variance.exr").channels["Y"])
    scatter = np.var(np.asarray(luminances, dtype=float), axis=0, ddof=1).ravel()
    spp = scene["film"]["spp"]
    mean_reported = np.mean(np.asarray(reported, dtype=float), axis=0).ravel() * spp / (spp - 1)
    ratio = scatter.sum() / mean_reported.sum()
    error = np.std(scatter - ratio * mean_reported, ddof=1) / (np.sqrt(scatter.size) * mean_reported.mean())
    assert abs(ratio - 1.0) <= 4.0 * error, (ratio, error)
    assert error < 0.07, error  # the check has power: a scale error of 30 % fails it
