"""``hg_path`` render time of this tree against another checkout (e.g. the previous commit), A B A B.

    python -m bench.bench_compare --baseline-tree /path/to/other/worktree [--rounds 3]

For each scene (the Cornell box and the thin-film example, 128×128 px, 64 spp, the scenes' own depth and
16 bands) every round runs one fresh subprocess per tree, alternating which goes first; a subprocess
compiles the kernels with two warm-up renders (other seeds) and then times ``Renderer.render_sums`` (its
sums end in host copies, so lazy evaluation cannot hide work) ``REPEATS`` times, keeping the median. The
report gives each tree's median over rounds and the ratio this/baseline. On a shared machine the spread
between rounds is reported too: read ratios within it as noise.

Results go to stdout and ``bench/results/integrator_compare.json`` (written atomically).
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
SCENES = ("cornell_box.json", "thin_film_cylinder_light.json")
SIZE_PX, SPP, BANDS, REPEATS = 128, 64, 16, 3


def _probe(scene_name: str) -> float:
    """Median seconds of REPEATS timed renders of ``scene_name`` in this process (after warm-up)."""
    from schemas.validation import validate_scene
    from worker import mitsuba_setup

    if hasattr(mitsuba_setup, "configure_mitsuba"):  # older trees chose the variant when imported
        mitsuba_setup.configure_mitsuba("llvm_ad_spectral")
    from worker.render.chunks import renderer_for

    data = json.loads((ROOT / "schemas" / "examples" / scene_name).read_text())
    data["film"] = {**data["film"], "width": SIZE_PX, "height": SIZE_PX, "spp": SPP, "bands": BANDS}
    renderer = renderer_for(validate_scene(data))
    for seed in (101, 102):
        renderer.render_sums(SPP, seed)
    times = []
    for seed in range(REPEATS):
        start = time.perf_counter()
        renderer.render_sums(SPP, seed)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _run(tree: Path, scene_name: str) -> float:
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    command = [sys.executable, "-c", f"import bench.bench_compare as b; print(b._probe({scene_name!r}))"]
    output = subprocess.run(command, cwd=tree, env=environment, capture_output=True, text=True, check=True)
    return float(output.stdout.strip().splitlines()[-1])


def main(baseline_tree: Path, rounds: int) -> dict[str, Any]:
    # The probe function is this file's; the baseline tree may not have it, so copy it there for the run.
    probe_copy = baseline_tree / "bench" / "bench_compare.py"
    created = not probe_copy.exists()
    if created:
        probe_copy.write_text(Path(__file__).read_text())
    try:
        results: dict[str, Any] = {}
        for scene_name in SCENES:
            this, base = [], []
            for index in range(rounds):
                order = [(ROOT, this), (baseline_tree, base)]
                for tree, sink in order if index % 2 == 0 else order[::-1]:
                    sink.append(_run(tree, scene_name))
            results[scene_name] = {
                "this_s": statistics.median(this),
                "baseline_s": statistics.median(base),
                "ratio": statistics.median(this) / statistics.median(base),
                "this_rounds_s": this,
                "baseline_rounds_s": base,
            }
            print(scene_name, json.dumps(results[scene_name]))
    finally:
        if created:
            probe_copy.unlink()
    report = {
        "size_px": SIZE_PX,
        "spp": SPP,
        "bands": BANDS,
        "baseline_tree": str(baseline_tree),
        "note": "shared machine: compare ratios with the spread between rounds",
        "scenes": results,
    }
    from bench.machine import write_results  # here: probes run this script with another tree's path

    write_results("integrator_compare", report)
    return report


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline-tree", type=Path, required=True, help="checkout to compare against")
    parser.add_argument("--rounds", type=int, default=3, help="A/B rounds per scene (alternating order)")
    arguments = parser.parse_args()
    main(arguments.baseline_tree.resolve(), arguments.rounds)
