"""Mitsuba's built-in ``path`` integrator as a reference for ``hg_path``, and the statistics to compare them.

Reference film. ``compiled.reference_dict`` is the scene with Mitsuba's own BSDFs; its sensor's film is
replaced by a ``specfilm`` with one box sensor-response function per band of our layout, of height 1/Δ_b
over [λ_b, λ_b + Δ_b]. ``specfilm`` samples wavelengths ∝ the summed SRFs and records
∫ SRF_b(λ) L(λ) dλ, so each channel estimates the band-averaged spectral radiance (1/Δ_b)∫_b L dλ — the
quantity our ``S0.<λ>nm`` channels hold (worker.render.spectral). A box pixel filter keeps pixels
independent (the default Gaussian filter would share samples between neighbours).

Standard error of an image mean. The image mean of band b is m = (1/P) Σ_p x̄_p over P pixels. Pixels are
rendered from independent samples, so Var(m) = (1/P²) Σ_p Var(x̄_p):
* ``hg_path``: ``variance.exr`` holds Var(x̄_p) (sample variance / N per pixel), so SE = √(Σ_p v_p) / P;
* ``path``: K renders with independent seeds give x̄_p = (1/K) Σ_k y_pk and the unbiased estimate
  Var(x̄_p) ≈ s_p² / K from the spread s_p² of the K values; SE = √(Σ_p s_p² / K) / P. Pooling the P
  per-pixel spreads (P·(K − 1) degrees of freedom) makes this estimate far steadier than the spread of K
  image means would be.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.settings import SceneLimits
from schemas.validation import validate_scene
from tests.support.exr import read_channels, spectral_stack
from worker.mitsuba_setup import configured_mitsuba
from worker.render.chunks import render_scene
from worker.render.scene_compiler import CompiledScene, SceneCompiler


@dataclass(frozen=True)
class BandMeans:
    """Per-band image means (W·m⁻²·sr⁻¹·nm⁻¹) and their Monte Carlo standard errors, shape (B,)."""

    mean: np.ndarray
    standard_error: np.ndarray


def image_mean_with_error(pixel_means: np.ndarray, pixel_mean_variances: np.ndarray) -> BandMeans:
    """Image mean over the leading two (pixel) axes, SE = √(Σ_p Var(x̄_p)) / P for independent pixels."""
    pixel_count = pixel_means.shape[0] * pixel_means.shape[1]
    mean = pixel_means.mean(axis=(0, 1))
    standard_error = np.sqrt(pixel_mean_variances.sum(axis=(0, 1))) / pixel_count
    return BandMeans(mean, standard_error)


def band_box_specfilm(compiled: CompiledScene) -> dict[str, Any]:
    """A ``specfilm`` whose channels are box SRFs of height 1/Δ_b matching ``compiled.bands``."""
    film = compiled.scene.film
    bands = compiled.bands
    height = 1.0 / bands.width_nm
    specfilm: dict[str, Any] = {
        "type": "specfilm",
        "width": film.width,
        "height": film.height,
        "component_format": "float32",
        "rfilter": {"type": "box"},
    }
    edges = bands.edges_nm
    for band in range(bands.band_count):
        # Zero-padded names: specfilm orders its channels alphabetically.
        specfilm[f"band_{band:03d}"] = {
            "type": "regular",
            "wavelength_min": float(edges[band]),
            "wavelength_max": float(edges[band + 1]),
            "values": f"{height!r}, {height!r}",
        }
    return specfilm


def path_band_means(mi: Any, compiled: CompiledScene, spp: int, seeds: list[int]) -> BandMeans:
    """Band means of Mitsuba's ``path`` (same max depth) over ``len(seeds)`` independent renders."""
    if len(seeds) < 2:
        raise ValueError(f"seeds: need at least two independent renders for a spread, got {len(seeds)}")
    scene_dict = dict(compiled.reference_dict)
    scene_dict["sensor"] = {**scene_dict["sensor"], "film": band_box_specfilm(compiled)}
    scene_dict["integrator"] = {"type": "path", "max_depth": compiled.scene.film.max_depth}
    scene = mi.load_dict(scene_dict, optimize=False)
    renders = np.stack([np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64) for seed in seeds])
    return image_mean_with_error(renders.mean(axis=0), renders.var(axis=0, ddof=1) / len(seeds))


PATH_SEEDS = list(range(8))
MAX_RELATIVE_STANDARD_ERROR = 0.03


def hg_band_means(scene: dict[str, Any], out_dir: Path, seed: int) -> BandMeans:
    """Render with ``hg_path`` through the public API and read the band means and their SE from the EXRs."""
    render_scene(validate_scene(scene), out_dir, seed=seed)
    names, bands = spectral_stack(read_channels(out_dir / "image.exr"))
    variance = read_channels(out_dir / "variance.exr")
    variances = np.stack([variance[name] for name in names], axis=-1)
    return image_mean_with_error(bands, variances)


def assert_agreement(scene: dict[str, Any], out_dir: Path, path_spp: int) -> None:
    mi = configured_mitsuba()
    compiled = SceneCompiler(mi, limits=SceneLimits()).compile(validate_scene(scene))
    ours = hg_band_means(scene, out_dir, seed=11)
    reference = path_band_means(mi, compiled, path_spp, PATH_SEEDS)
    combined = np.sqrt(ours.standard_error**2 + reference.standard_error**2)
    z_scores = (ours.mean - reference.mean) / combined
    print("hg_path", ours.mean, "\npath   ", reference.mean, "\nz      ", np.round(z_scores, 2))
    assert np.all(reference.mean > 0) and np.all(ours.mean > 0)
    assert np.all(ours.standard_error <= MAX_RELATIVE_STANDARD_ERROR * ours.mean)
    assert np.all(reference.standard_error <= MAX_RELATIVE_STANDARD_ERROR * reference.mean)
    assert np.all(np.abs(z_scores) <= 3.0), f"bands beyond 3σ: z = {np.round(z_scores, 2)}"
