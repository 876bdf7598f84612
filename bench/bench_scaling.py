"""Whole-render cost per sample from 128² to 4096², and peak memory at 32 bands (issue 16, items 1-2).

Measured:

* cost per sample: the Cornell box example at N×N px, ``SPP`` spp, ``BANDS`` bands, max depth 8, in
  ``llvm_ad_spectral``, rendered through the public API (``worker.render.chunks.render_scene``: tiles,
  accumulation, images and EXR writing included) in a fresh subprocess per measurement. JIT compilation
  is reported apart: the subprocess first renders the scene at 32² (which compiles the kernels; the
  timed render hits Dr.Jit's kernel cache, its IR does not depend on the image size) and reports that
  warm-up's time. seconds/sample = render wall time / (N²·spp); ratio = that / the 128² figure.
* peak RSS: ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` (KiB on Linux) of the subprocess after the
  warm-up (modules, scene, kernels: the "load" phase) and after the timed render (the whole render:
  tiles, image building, EXR writing), at 32 bands and ``MEMORY_SPP`` spp; and the same for a
  noise-target render (``noise_target_memory``: rounds from ``NOISE_FIRST_SPP`` spp until the band means'
  relative error is ``NOISE_TARGET_REL_ERROR``, a fixed schedule for a given seed: at 1024² three rounds).
* A/B: with ``--baseline-pythonpath DIR`` each measurement alternates between this checkout (B) and the
  code at DIR (A, e.g. main's checkout), ``--repeats`` pairs, medians; sizes listed in
  ``--baseline-max-px`` and below only (the baseline's memory grows with the image).

Results go to stdout and ``bench/results/scaling.json`` (written atomically).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.bench_integrator import MAX_DEPTH, example_scene

ROOT = Path(__file__).resolve().parent.parent
SCENE = "cornell_box"
SPP = 16
BANDS = 16
MEMORY_SPP = 4
MEMORY_BANDS = 32
NOISE_FIRST_SPP = 2
NOISE_TARGET_REL_ERROR = 0.0025
WARMUP_PX = 32
TARGET_RATIO = 1.1


def _scene(resolution_px: int, spp: int, bands: int) -> dict[str, Any]:
    """The Cornell box example with the benchmark's film (1 HG mode, its default; max depth 8)."""
    return example_scene(SCENE, resolution_px, spp, bands, modes=1)


def probe(resolution_px: int, spp: int, bands: int, target_rel_error: float = 0.0) -> dict[str, Any]:
    """In this process: warm up at ``WARMUP_PX``, then time one render (with a noise target when
    ``target_rel_error`` > 0, ``spp`` its first round's); seconds and peak RSS per phase."""
    from hgcore.noise_target import NoiseTarget
    from schemas.validation import validate_scene
    from worker import mitsuba_setup

    if hasattr(mitsuba_setup, "configure_mitsuba"):  # older trees chose the variant when imported
        mitsuba_setup.configure_mitsuba("llvm_ad_spectral")
    from worker.render.chunks import render_scene

    target = NoiseTarget(rel_error=target_rel_error) if target_rel_error > 0 else None

    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        render_scene(validate_scene(_scene(WARMUP_PX, 1, bands)), Path(tmp) / "warmup")
        warmup_s = time.perf_counter() - start
        load_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        start = time.perf_counter()
        scene = validate_scene(_scene(resolution_px, spp, bands))
        summary = render_scene(scene, Path(tmp) / "render", target=target)
        render_s = time.perf_counter() - start
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    spp = summary["spp"]
    samples = resolution_px * resolution_px * spp
    return {
        "resolution_px": resolution_px,
        "spp": spp,
        "target_rel_error": target_rel_error or None,
        "bands": bands,
        "warmup_s": warmup_s,
        "render_s": render_s,
        "seconds_per_sample": render_s / samples,
        "peak_rss_load_mib": load_kib / 1024,
        "peak_rss_mib": peak_kib / 1024,
    }


def run_probe(
    pythonpath: Path, resolution_px: int, spp: int, bands: int, target_rel_error: float = 0.0
) -> dict[str, Any]:
    """``probe`` in a fresh subprocess importing the code at ``pythonpath``."""
    # The script runs by path, so that ``pythonpath`` alone decides which ``worker`` it imports.
    env = {**os.environ, "PYTHONPATH": str(pythonpath), "HGRENDER_VARIANT": "llvm_ad_spectral"}
    script = Path(__file__).resolve()
    probe_args = [str(resolution_px), str(spp), str(bands), str(target_rel_error)]
    command = [sys.executable, str(script), "--probe", *probe_args]
    completed = subprocess.run(command, env=env, cwd=ROOT, capture_output=True, text=True, check=False)
    if completed.returncode != 0:
        return {"error": completed.stderr.strip().splitlines()[-1:], "resolution_px": resolution_px}
    return json.loads(completed.stdout.strip().splitlines()[-1])


def measure(
    sizes: list[int],
    spp: int,
    bands: int,
    repeats: int,
    baseline: Path | None,
    baseline_max_px: int,
    target_rel_error: float = 0.0,
) -> list[dict[str, Any]]:
    """Per size: the B (and A) probes, alternating, with the medians."""
    rows = []
    for size in sizes:
        sides = {"new": ROOT}
        if baseline is not None and size <= baseline_max_px:
            sides["baseline"] = baseline
        runs: dict[str, list[dict[str, Any]]] = {side: [] for side in sides}
        for _ in range(repeats if size <= 1024 else 1):
            for side, path in sides.items():
                runs[side].append(run_probe(path, size, spp, bands, target_rel_error))
        row: dict[str, Any] = {"resolution_px": size, "runs": runs}
        for side, results in runs.items():
            good = [r for r in results if "error" not in r]
            if good:
                row[side] = {
                    key: statistics.median(r[key] for r in good)
                    for key in (
                        "render_s",
                        "seconds_per_sample",
                        "warmup_s",
                        "peak_rss_mib",
                        "peak_rss_load_mib",
                    )
                }
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "runs"}), file=sys.stderr)
    for side in ("new", "baseline"):
        reference = next((r[side]["seconds_per_sample"] for r in rows if side in r), None)
        for row in rows:
            if side in row and reference:
                row[side]["ratio_to_smallest"] = row[side]["seconds_per_sample"] / reference
    return rows


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--probe", nargs=4, metavar=("PX", "SPP", "BANDS", "TARGET"), help=argparse.SUPPRESS)
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 512, 1024])
    parser.add_argument("--memory-sizes", type=int, nargs="*", default=[1024])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--baseline-pythonpath", type=Path)
    parser.add_argument("--baseline-max-px", type=int, default=1024)
    args = parser.parse_args(argv)
    if args.probe:
        px, spp, bands, target = args.probe
        print(json.dumps(probe(int(px), int(spp), int(bands), float(target))))  # one line, for run_probe
        sys.exit(0)
    from bench.machine import MachineLoad, write_results  # here: the probe also runs a baseline's code

    machine = MachineLoad()
    scaling = measure(args.sizes, SPP, BANDS, args.repeats, args.baseline_pythonpath, args.baseline_max_px)
    memory = measure(
        args.memory_sizes, MEMORY_SPP, MEMORY_BANDS, 1, args.baseline_pythonpath, args.baseline_max_px
    )
    noise_target_memory = measure(
        args.memory_sizes,
        NOISE_FIRST_SPP,
        MEMORY_BANDS,
        1,
        args.baseline_pythonpath,
        args.baseline_max_px,
        NOISE_TARGET_REL_ERROR,
    )
    results = {
        "scene": SCENE,
        "spp": SPP,
        "bands": BANDS,
        "max_depth": MAX_DEPTH,
        "memory_spp": MEMORY_SPP,
        "memory_bands": MEMORY_BANDS,
        "variant": "llvm_ad_spectral",
        "target_ratio": TARGET_RATIO,
        "scaling": scaling,
        "memory": memory,
        "noise_target_memory": noise_target_memory,
        "baseline_pythonpath": str(args.baseline_pythonpath) if args.baseline_pythonpath else None,
        **machine.fields(),
    }
    write_results("scaling", results)
    return results


if __name__ == "__main__":
    json.dump(main(sys.argv[1:]), sys.stdout, indent=2)
    sys.stdout.write("\n")
