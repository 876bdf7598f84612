"""``hg_path`` against Mitsuba's built-in ``path`` integrator, 1 vs 16 HG modes, and peak render memory.

Measured (issue 3, "Performance"; targets: 1 mode ≤ 1.5× ``path``, 16 modes ≤ 3× 1 mode):

* the Cornell box example (``schemas/examples/cornell_box.json``) at 128×128 px, 64 spp, max depth 8, 16
  bands, in ``llvm_ad_spectral`` for both integrators, in one process. ``hg_path`` runs through
  ``worker.render.renderer.Renderer.render_sums`` (its per-pixel sums end in host ``np.asarray`` copies);
  ``path`` renders ``compiled.reference_dict`` (Mitsuba's own BSDFs, RGB ``hdrfilm``) and its image is copied
  with ``np.array``, so lazy evaluation cannot hide work in either timed region.
* JIT compilation is excluded: two warm-up renders compile the kernels; the timed renders that follow use
  other seeds and hit Dr.Jit's kernel cache (compiled kernels are keyed by the hash of their IR, and the
  seed is not part of it). The warm-up times and, from Dr.Jit's kernel history, the LLVM compilation time
  of cache misses are reported separately; the timed runs report theirs too (it should be 0). Timed rounds
  interleave the integrators and each keeps its best of ``repeats`` (the machine is shared).
* samples/s = width·height·spp / seconds; ratios hg(1 mode)/path and hg(16 modes)/hg(1 mode).
* peak memory: a 1024×1024, 32-band render of the same scene at ``MEMORY_SPP`` spp through the public API
  (``worker.render.chunks.render_scene``, EXR writing included) in a fresh subprocess, whose
  ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` is the peak resident set (KiB on Linux); skipped by
  ``--quick``.

Results go to stdout and ``bench/results/integrator.json`` (written atomically).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench.machine import cpu_model, cpu_reference_s, write_results
from schemas import EXAMPLES_DIR

CORNELL_SCENE = "cornell_box"
THIN_FILM_SCENE = "thin_film_sphere_light"
VARIANT = "llvm_ad_spectral"
RESOLUTION_PX = 128
SPP = 64
MAX_DEPTH = 8
BANDS = 16
REPEATS = 5
MEMORY_RESOLUTION_PX = 1024
MEMORY_BANDS = 32
MEMORY_SPP = 4
TARGET_HG_OVER_PATH = 1.5
TARGET_16_OVER_1 = 3.0


def example_scene(name: str, resolution_px: int, spp: int, bands: int, modes: int) -> dict[str, Any]:
    """An example scene of ``schemas/examples`` with the benchmark's film settings (max depth 8)."""
    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    scene["film"] = {
        **scene["film"],
        "width": resolution_px,
        "height": resolution_px,
        "spp": spp,
        "bands": bands,
        "modes": modes,
        "max_depth": MAX_DEPTH,
    }
    return scene


def _jit_costs(history: list[dict[str, Any]]) -> dict[str, float]:
    """From a Dr.Jit kernel history: LLVM compilation of cache misses, their count, and IR assembly time.

    ``backend_time`` (ms) is spent only on kernels missing from the in-memory and on-disk caches;
    ``codegen_time`` (ms, assembling and hashing the IR) is paid by every launch, cached or not.
    """
    jit_kernels = [entry for entry in history if "cache_hit" in entry]
    misses = [entry for entry in jit_kernels if not entry["cache_hit"]]
    return {
        "llvm_compile_s": sum(entry.get("backend_time", 0.0) for entry in misses) / 1e3,
        "cache_misses": len(misses),
        "ir_assembly_s": sum(entry.get("codegen_time", 0.0) for entry in jit_kernels) / 1e3,
    }


def _time_renders(renders: dict[str, Callable[[int], Any]], samples: int, repeats: int) -> dict[str, Any]:
    """Warm up each render twice, then time ``repeats`` rounds that run every render once, interleaved.

    Two warm-up renders because ``hg_path``'s first launch after ``Renderer()`` compiles a different
    kernel (same operations, other IR order) than every later one (see the report). Interleaving spreads
    the shared machine's load changes over all integrators alike; each keeps its best round.
    """
    import drjit as dr

    results: dict[str, Any] = {}
    for name, render in renders.items():
        dr.kernel_history()  # drop earlier entries
        warm_up_s = []
        for seed in (0, 1):
            start = time.perf_counter()
            render(seed)
            warm_up_s.append(time.perf_counter() - start)
        results[name] = {
            "warm_up_s": warm_up_s,
            "warm_up_jit": _jit_costs(dr.kernel_history()),
            "timed_s": [],
        }
    timed_history: dict[str, list[dict[str, Any]]] = {name: [] for name in renders}
    for seed in range(2, repeats + 2):
        for name, render in renders.items():
            start = time.perf_counter()
            render(seed)
            results[name]["timed_s"].append(time.perf_counter() - start)
            timed_history[name] += dr.kernel_history()
    for name, result in results.items():
        best = min(result["timed_s"])
        result.update(
            timed_jit=_jit_costs(timed_history[name]),
            best_s=best,
            samples=samples,
            samples_per_s=samples / best,
        )
    return results


def _renderer(mi: Any, scene: dict[str, Any]) -> Any:
    from hgcore.settings import SceneLimits
    from schemas.validation import validate_scene
    from worker.render.renderer import Renderer
    from worker.render.scene_compiler import SceneCompiler

    return Renderer(SceneCompiler(mi, limits=SceneLimits()).compile(validate_scene(scene)))


def _hg_renders(mi: Any, scene_name: str) -> dict[str, Callable[[int], Any]]:
    """hg_path renders (per-pixel sums copied to the host) with 1 and with 16 HG modes."""
    renders = {}
    for modes in (1, 16):
        renderer = _renderer(mi, example_scene(scene_name, RESOLUTION_PX, SPP, BANDS, modes))
        renders[f"hg_path_{modes}_mode{'s' if modes > 1 else ''}"] = lambda seed, renderer=renderer: (
            renderer.render_sums(SPP, seed)
        )
    return renders


def measure_speed(repeats: int = REPEATS) -> dict[str, Any]:
    """hg_path (1 and 16 modes) vs path on the Cornell box, and 1 vs 16 modes on a thin-film scene.

    The Cornell box has no coherence-sensitive material, so there the modes cost nothing by construction;
    the Fig. 7 thin-film scene (sphere light) is where they are evaluated (visibilities per film vertex).
    """
    from worker.mitsuba_setup import configure_mitsuba

    mi = configure_mitsuba(VARIANT)
    import drjit as dr

    samples = RESOLUTION_PX * RESOLUTION_PX * SPP
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        cornell_renders = _hg_renders(mi, CORNELL_SCENE)
        reference = dict(
            _renderer(mi, example_scene(CORNELL_SCENE, RESOLUTION_PX, SPP, BANDS, 1)).compiled.reference_dict
        )
        reference["integrator"] = {"type": "path", "max_depth": MAX_DEPTH}
        path_scene = mi.load_dict(reference, optimize=False)
        cornell_renders["path"] = lambda seed: np.array(mi.render(path_scene, spp=SPP, seed=seed))
        cornell = _time_renders(cornell_renders, samples, repeats)
        thin_film = _time_renders(_hg_renders(mi, THIN_FILM_SCENE), samples, repeats)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    for timings in (cornell, thin_film):
        timings["ratio_16_modes_over_1_mode"] = (
            timings["hg_path_16_modes"]["best_s"] / timings["hg_path_1_mode"]["best_s"]
        )
    cornell["ratio_hg_1_mode_over_path"] = cornell["hg_path_1_mode"]["best_s"] / cornell["path"]["best_s"]
    return {
        CORNELL_SCENE: cornell,
        THIN_FILM_SCENE: thin_film,
        "targets": {"hg_over_path_max": TARGET_HG_OVER_PATH, "16_over_1_max": TARGET_16_OVER_1},
        "targets_met": {
            "hg_over_path": cornell["ratio_hg_1_mode_over_path"] <= TARGET_HG_OVER_PATH,
            "16_over_1": max(cornell["ratio_16_modes_over_1_mode"], thin_film["ratio_16_modes_over_1_mode"])
            <= TARGET_16_OVER_1,
        },
    }


def _memory_probe() -> dict[str, Any]:
    """Run in a fresh process: peak RSS of one 1024×1024, 32-band render through the public API."""
    from schemas.validation import validate_scene
    from worker.mitsuba_setup import configure_mitsuba

    configure_mitsuba(VARIANT)
    from worker.render.chunks import render_scene

    scene = validate_scene(example_scene(CORNELL_SCENE, MEMORY_RESOLUTION_PX, MEMORY_SPP, MEMORY_BANDS, 1))
    baseline_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as out_dir:
        render_scene(scene, Path(out_dir))
    seconds = time.perf_counter() - start
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "resolution_px": [MEMORY_RESOLUTION_PX, MEMORY_RESOLUTION_PX],
        "bands": MEMORY_BANDS,
        "spp": MEMORY_SPP,
        "seconds": seconds,
        "peak_rss_mib": peak_kib / 1024.0,
        "rss_before_render_mib": baseline_kib / 1024.0,
    }


def measure_memory() -> dict[str, Any]:
    """``_memory_probe`` in a subprocess, so that the peak is the render's and not this process's."""
    completed = subprocess.run(
        [sys.executable, "-m", "bench.bench_integrator", "--memory-probe"],
        cwd=Path(__file__).resolve().parents[1],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "HGRENDER_VARIANT": VARIANT},
    )
    return json.loads(completed.stdout)


def main(quick: bool = False, repeats: int = REPEATS) -> dict[str, Any]:
    """Run the measurements (without the 1024² memory render when ``quick``) and write the results."""
    import drjit as dr

    results: dict[str, Any] = {
        "variant": VARIANT,
        "drjit_version": dr.__version__,
        "cpu": cpu_model(),
        "cpu_reference_s": cpu_reference_s(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "resolution_px": [RESOLUTION_PX, RESOLUTION_PX],
        "spp": SPP,
        "max_depth": MAX_DEPTH,
        "bands": BANDS,
        **measure_speed(repeats),
    }
    results["memory"] = None if quick else measure_memory()
    write_results("integrator", results)
    return results


def _parse_arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m bench.bench_integrator", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--quick", action="store_true", help="skip the 1024×1024, 32-band memory render")
    parser.add_argument(
        "--repeats", type=int, default=REPEATS, help="timed renders per integrator (best kept)"
    )
    parser.add_argument("--memory-probe", action="store_true", help=argparse.SUPPRESS)
    arguments = parser.parse_args(argv)
    if arguments.repeats < 1:
        parser.error(f"--repeats: must be at least 1, got {arguments.repeats}")
    return arguments


if __name__ == "__main__":
    arguments = _parse_arguments()
    if arguments.memory_probe:
        json.dump(_memory_probe(), sys.stdout)
    else:
        json.dump(main(quick=arguments.quick, repeats=arguments.repeats), sys.stdout, indent=2)
    sys.stdout.write("\n")
