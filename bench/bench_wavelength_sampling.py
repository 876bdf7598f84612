"""Colour noise and cost of ``film.wavelength_sampling``: ``uniform`` vs ``importance`` at fixed spp.

Scenes: the shipped thin-film examples (F11 sphere and cylinder lamps) and the Cornell box with its lamp
replaced by F11 and by F7 (diffuse only), plus the shipped Cornell box (D65) as the smooth-spectrum
control; 64×64, 16 bands, at 16 and 64 spp.

Chroma RMS noise. Each setting renders ``SEEDS`` independent images; per pixel the variance over the seeds
of CIELAB a* and b* (the image's linear sRGB, white = the 99th percentile of the pixel luminance averaged
over every render of the scene, the same for both modes) is summed, and the chroma RMS noise is
√(mean over lit pixels of Var a* + Var b*). Lit: mean luminance ≥ 1 % of that white. The variance ratio
is (RMS_uniform / RMS_importance)²; its relative standard error comes from the spread of the per-pixel
variances (√(s²/P) / mean for each mode, combined).

Cost. CPU seconds (``time.process_time``, all threads: robust to the other users of the machine) of a
``COST_SPP`` render per mode, after one warm-up render each (kernels compiled), alternated A/B for
``ROUNDS`` rounds; medians, µs per sample, and the median of the per-round ratios.

Results: stdout and ``bench/results/wavelength_sampling.json``.
"""

from __future__ import annotations

import copy
import json
import math
import statistics
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from bench.machine import MachineLoad, write_results
from hgcore.artifacts.images import images_from_sums
from hgcore.colour import linear_srgb_to_lab
from schemas import EXAMPLES_DIR
from schemas.validation import validate_scene
from worker.mitsuba_setup import configure_mitsuba

if TYPE_CHECKING:
    from worker.render.renderer import Renderer

MODES = ("uniform", "importance")
SPPS = (16, 64)
SEEDS = (1, 2, 3, 4)
ROUNDS = 7  # A/B pairs for the cost
COST_SPP = 256  # 1 M samples per timed render at 64²: long enough to time under load
SIZE_PX = 64
BANDS = 16


def _example(name: str) -> dict[str, Any]:
    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    scene["film"] = {**scene["film"], "width": SIZE_PX, "height": SIZE_PX, "bands": BANDS}
    return scene


def _with_lamp(scene: dict[str, Any], name: str) -> dict[str, Any]:
    scene = copy.deepcopy(scene)
    for emitter in scene["emitters"]:
        emitter["spectrum"] = {"type": "cie_f", "name": name}
    return scene


def scenes() -> dict[str, dict[str, Any]]:
    cornell = _example("cornell_box")
    return {
        "thin_film_sphere_light (F11)": _example("thin_film_sphere_light"),
        "thin_film_cylinder_light (F11)": _example("thin_film_cylinder_light"),
        "cornell_box F11": _with_lamp(cornell, "F11"),
        "cornell_box F7": _with_lamp(cornell, "F7"),
        "cornell_box D65 (control)": cornell,
    }


def _renderer(scene: dict[str, Any], mode: str) -> Renderer:
    from hgcore.settings import SceneLimits
    from worker.mitsuba_setup import configured_mitsuba
    from worker.render.renderer import Renderer
    from worker.render.scene_compiler import SceneCompiler

    scene = {**scene, "film": {**scene["film"], "wavelength_sampling": mode}}
    return Renderer(SceneCompiler(configured_mitsuba(), limits=SceneLimits()).compile(validate_scene(scene)))


def _rgb(renderer: Renderer, spp: int, seed: int) -> np.ndarray:
    images = images_from_sums(renderer.render_sums(spp, seed), renderer.compiled.bands)
    return images["rgb"].reshape(-1, 3).astype(np.float64)


def chroma_noise(renders: dict[str, list[np.ndarray]]) -> dict[str, Any]:
    """Chroma RMS noise per mode from same-setting renders over seeds, and the variance ratio."""
    every = np.concatenate([np.stack(images) for images in renders.values()])
    mean_y = every[..., 1].mean(axis=0)
    white = float(np.percentile(mean_y, 99))
    lit = mean_y >= 0.01 * white
    result: dict[str, Any] = {"lit_pixels": int(lit.sum()), "white_luminance": white}
    spread = {}
    for mode, images in renders.items():
        lab = linear_srgb_to_lab(np.stack(images)[:, lit], white_level=white)
        per_pixel = lab[..., 1:].var(axis=0, ddof=1).sum(axis=-1)
        spread[mode] = per_pixel
        result[f"chroma_rms_{mode}"] = math.sqrt(per_pixel.mean())
    ratio = spread["uniform"].mean() / spread["importance"].mean()
    relative = math.hypot(
        *(values.std() / (values.mean() * math.sqrt(values.size)) for values in spread.values())
    )
    result["variance_ratio"] = ratio
    result["variance_ratio_se"] = ratio * relative
    return result


def cost(scene: dict[str, Any], spp: int) -> dict[str, Any]:
    renderers = {mode: _renderer(scene, mode) for mode in MODES}
    for renderer in renderers.values():
        renderer.render_sums(spp, 0)  # compile
    times: dict[str, list[float]] = {mode: [] for mode in MODES}
    for round_index in range(ROUNDS):
        order = MODES if round_index % 2 == 0 else MODES[::-1]
        for mode in order:
            start = time.process_time()
            renderers[mode].render_sums(spp, 100 + round_index)
            times[mode].append(time.process_time() - start)
    samples = SIZE_PX * SIZE_PX * spp
    medians = {mode: statistics.median(values) for mode, values in times.items()}
    return {
        "cpu_s": times,
        "median_cpu_s": medians,
        "us_per_sample": {mode: 1e6 * value / samples for mode, value in medians.items()},
        "importance_over_uniform": medians["importance"] / medians["uniform"],
        "median_round_ratio": statistics.median(
            a / b for a, b in zip(times["importance"], times["uniform"], strict=True)
        ),
    }


def main() -> dict[str, Any]:
    configure_mitsuba("llvm_ad_spectral")
    load = MachineLoad()
    results: dict[str, Any] = {}
    for name, scene in scenes().items():
        entry: dict[str, Any] = {}
        for spp in SPPS:
            renderers = {mode: _renderer(scene, mode) for mode in MODES}
            renders = {mode: [_rgb(renderers[mode], spp, seed) for seed in SEEDS] for mode in MODES}
            entry[f"{spp}spp"] = chroma_noise(renders)
            print(name, spp, json.dumps(entry[f"{spp}spp"]), flush=True)
        entry["cost"] = cost(scene, COST_SPP)
        print(name, "cost", json.dumps(entry["cost"]["median_round_ratio"]), flush=True)
        results[name] = entry
    report = {
        "what": "chroma RMS noise (CIELAB a*, b* over seeds) and CPU cost: wavelength_sampling uniform vs "
        "importance",
        "size_px": SIZE_PX,
        "bands": BANDS,
        "seeds": list(SEEDS),
        "rounds": ROUNDS,
        "cost_spp": COST_SPP,
        "scenes": results,
        **load.fields(),
    }
    write_results("wavelength_sampling", report)
    return report


if __name__ == "__main__":
    main()
