"""Where ``hg_path``'s time goes: Dr.Jit kernel history of a render, against Mitsuba ``path``/``prb`` and
against other checkouts, alternating A B A B (issue 16 item 3, issue 12 "Performance").

    python -m bench.bench_kernel_profile [--tree NAME=PATH ...] [--rounds 3] [--scenes cornell_box ...]

Each round runs, for every tree in turn (the order alternates between rounds), one fresh subprocess per
scene that builds the scene (128×128 px, 64 spp, 16 bands, the scene's modes (1) and depth), renders
twice to compile (other seeds; Mitsuba's once), and then times ``REPEATS`` renders of
``Renderer.render_sums`` (its sums end in host copies, so lazy evaluation cannot hide work). This tree's
subprocess also times Mitsuba's ``path`` and ``prb`` on the same loaded scene
(``compiled.reference_dict``: Mitsuba's own BSDFs, RGB ``hdrfilm``, same depths), interleaved with
``hg_path`` in an order that reverses every repeat; ``prb_rr_matched`` is prb with its roulette starting
at the same vertex as ``path``'s and ``hg_path``'s (prb.py counts ``rr_depth`` one vertex later).

Per render it records the CPU time (``time.process_time``: both worker threads, robust to the other
users of a shared machine) and the wall time, and from Dr.Jit's kernel history (``JitFlag.KernelHistory``)
the megakernel's execution time and operation count, the IR assembly (``codegen_time``, paid by every
launch) and the LLVM compilation (``backend_time`` of cache misses: 0 once warm) of all kernels, and the
time outside kernels (tracing the Python loop body, host copies and sums: CPU − kernel CPU is not
separable on two threads, so wall − kernel wall is reported). The report keeps medians over renders and
rounds, and the ratios hg_path/path, hg_path/prb and this/each other tree of the medians; against
Mitsuba's integrators also ``paired_ratios``, the medians of per-pair ratios (render i of ``hg_path``
over render i of the other, adjacent in one process), which cancel the drift between renders.

Results go to stdout and ``bench/results/kernel_profile.json`` (written atomically).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("cornell_box", "thin_film_cylinder_light")
SIZE_PX, SPP, BANDS, REPEATS = 128, 64, 16, 4  # REPEATS even: each order equally often


PAIRED_METRICS = ("cpu_s", "wall_s", "megakernel_exec_s")


def _render_record(render: Any, seed: int) -> dict[str, float]:
    """Time one render and read the kernel history it left (the history must be on and drained)."""
    import drjit as dr

    wall_start, cpu_start = time.perf_counter(), time.process_time()
    render(seed)
    cpu_s, wall_s = time.process_time() - cpu_start, time.perf_counter() - wall_start
    kernels = [entry for entry in dr.kernel_history() if entry.get("type") == dr.KernelType.JIT]
    mega = max(kernels, key=lambda entry: entry.get("operation_count", 0))
    kernel_s = sum(entry.get("execution_time", 0.0) for entry in kernels) / 1e3
    return {
        "cpu_s": cpu_s,
        "wall_s": wall_s,
        "kernels": len(kernels),
        "kernel_exec_s": kernel_s,
        "megakernel_exec_s": mega.get("execution_time", 0.0) / 1e3,
        "megakernel_ops": mega.get("operation_count", 0),
        "codegen_s": sum(entry.get("codegen_time", 0.0) for entry in kernels) / 1e3,
        "llvm_compile_s": sum(entry.get("backend_time", 0.0) for entry in kernels if not entry["cache_hit"])
        / 1e3,
        "outside_kernels_wall_s": wall_s - kernel_s,
    }


def _probe(scene_name: str, with_mitsuba: bool) -> dict[str, list[dict[str, float]]]:
    """Run in a subprocess of a tree: warm up, then ``REPEATS`` interleaved timed renders per integrator."""
    import numpy as np

    from schemas.validation import validate_scene
    from worker.mitsuba_setup import configure_mitsuba

    mi = configure_mitsuba("llvm_ad_spectral")
    import drjit as dr

    from worker.render.chunks import renderer_for

    data = json.loads((ROOT / "schemas" / "examples" / f"{scene_name}.json").read_text())
    data["film"] = {**data["film"], "width": SIZE_PX, "height": SIZE_PX, "spp": SPP, "bands": BANDS}
    renderer = renderer_for(validate_scene(data))
    renders: dict[str, Any] = {"hg_path": lambda seed: renderer.render_sums(SPP, seed)}
    if with_mitsuba:
        rr_depth = renderer.integrator.rr_depth
        # prb.py starts its roulette one vertex later than Mitsuba's ``path`` and ``hg_path`` for the same
        # ``rr_depth`` (it tests the depth before counting the vertex): ``prb_rr_matched`` starts it at
        # the same vertex, the like-for-like estimator; ``prb`` is prb at its default.
        integrators = {
            "path": {"type": "path", "rr_depth": rr_depth},
            "prb": {"type": "prb", "rr_depth": rr_depth},
            "prb_rr_matched": {"type": "prb", "rr_depth": rr_depth - 1},
        }
        for name, integrator in integrators.items():
            reference = dict(renderer.compiled.reference_dict)
            reference["integrator"] = {**integrator, "max_depth": renderer.integrator.max_depth}
            scene = mi.load_dict(reference, optimize=False)
            renders[name] = lambda seed, scene=scene: np.array(mi.render(scene, spp=SPP, seed=seed))
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    records: dict[str, list[dict[str, float]]] = {name: [] for name in renders}
    warm_up: dict[str, list[dict[str, float]]] = {name: [] for name in renders}
    dr.kernel_history()
    for seed in (101, 102):  # hg_path's first render after Renderer() compiles another kernel: two
        for name, render in renders.items():
            if name == "hg_path" or seed == 101:
                warm_up[name].append(_render_record(render, seed))
    names = list(renders)
    for seed in range(REPEATS):
        # A B C D, D C B A, …: no integrator always runs first (after another's allocations) or last.
        for name in names if seed % 2 == 0 else names[::-1]:
            records[name].append(_render_record(renders[name], seed))
    return {"timed": records, "warm_up": warm_up}


def _run(tree: Path, scene_name: str, with_mitsuba: bool) -> dict[str, Any]:
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    code = (
        "import json, bench.bench_kernel_profile as b; "
        f"print(json.dumps(b._probe({scene_name!r}, {with_mitsuba!r})))"
    )
    output = subprocess.run(
        [sys.executable, "-c", code], cwd=tree, env=environment, capture_output=True, text=True, check=True
    )
    return json.loads(output.stdout.strip().splitlines()[-1])


def _medians(records: list[dict[str, float]]) -> dict[str, float]:
    return {key: statistics.median(record[key] for record in records) for key in records[0]}


def _add_pairs(paired: dict[str, dict[str, list[float]]], timed: dict[str, list[dict[str, float]]]) -> None:
    """Append this subprocess's per-pair ratios hg_path/X (render i of hg_path over render i of each
    Mitsuba integrator X, adjacent in time): a pair shares the machine's state of the moment, so its
    ratio cancels the drift between renders that a ratio of overall medians keeps."""
    for integrator, records in timed.items():
        if integrator == "hg_path":
            continue
        metrics = paired.setdefault(f"this/{integrator}", {})
        for ours, theirs in zip(timed["hg_path"], records, strict=True):
            for metric in PAIRED_METRICS:
                metrics.setdefault(metric, []).append(ours[metric] / theirs[metric])


def main(trees: dict[str, Path], rounds: int, scenes: list[str]) -> dict[str, Any]:
    """``trees``: name → checkout; the first is this tree (which also times Mitsuba's integrators)."""
    from bench.machine import MachineLoad, write_results

    load = MachineLoad()
    names = list(trees)
    copies = []
    for tree in trees.values():  # the probe is this file's: copy it into trees that lack it
        copy = tree / "bench" / "bench_kernel_profile.py"
        if not copy.exists():
            copy.write_text(Path(__file__).read_text())
            copies.append(copy)
    try:
        results: dict[str, Any] = {}
        for scene_name in scenes:
            per_render: dict[str, list[dict[str, float]]] = {}
            round_medians: dict[str, list[float]] = {}
            paired: dict[str, dict[str, list[float]]] = {}
            for index in range(rounds):
                order = names if index % 2 == 0 else names[::-1]
                for name in order:
                    probe = _run(trees[name], scene_name, with_mitsuba=name == names[0])
                    for integrator, records in probe["timed"].items():
                        key = name if integrator == "hg_path" else integrator
                        per_render.setdefault(key, []).extend(records)
                        round_medians.setdefault(key, []).append(
                            statistics.median(record["cpu_s"] for record in records)
                        )
                        if index == 0:
                            per_render.setdefault(f"{key}/warm_up", []).extend(probe["warm_up"][integrator])
                    if name == names[0]:
                        _add_pairs(paired, probe["timed"])
            summary = {key: _medians(records) for key, records in per_render.items()}
            this = summary[names[0]]
            ratios = {}
            for key in per_render:
                if key != names[0] and not key.endswith("/warm_up"):
                    ratios[f"{names[0]}/{key}"] = {
                        metric: this[metric] / summary[key][metric] for metric in PAIRED_METRICS
                    }
            paired_ratios = {
                key: {metric: statistics.median(values) for metric, values in metrics.items()}
                for key, metrics in paired.items()
            }
            results[scene_name] = {
                "medians": summary,
                "round_cpu_medians_s": round_medians,
                "ratios": ratios,
                "paired_ratios": paired_ratios,
                "paired_ratio_samples": paired,
            }
            print(scene_name, json.dumps({"ratios": ratios, "paired_ratios": paired_ratios}, indent=1))
    finally:
        for copy in copies:
            copy.unlink()
    report = {
        "size_px": SIZE_PX,
        "spp": SPP,
        "bands": BANDS,
        "repeats_per_round": REPEATS,
        "rounds": rounds,
        "trees": {name: str(path) for name, path in trees.items()},
        "note": "ratios: of the medians over all timed renders of all rounds; paired_ratios: medians of "
        "per-pair ratios (adjacent renders in one process); cpu_s = process_time (both threads)",
        **load.fields(),
        "scenes": results,
    }
    write_results("kernel_profile", report)
    return report


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", action="append", default=[], help="NAME=PATH of another checkout")
    parser.add_argument("--rounds", type=int, default=3, help="rounds (alternating the trees' order)")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), help="example scene names")
    arguments = parser.parse_args()
    others = dict(item.split("=", 1) for item in arguments.tree)
    trees = {"this": ROOT, **{name: Path(path).resolve() for name, path in others.items()}}
    main(trees, arguments.rounds, arguments.scenes)
