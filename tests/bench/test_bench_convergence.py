"""Smoke test of ``bench/bench_convergence.py --quick``: it runs, writes its JSON, and its numbers behave."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import pytest

from bench import bench_convergence


@pytest.mark.slow
def test_quick_convergence_bench_writes_consistent_results(tmp_path: Path) -> None:
    """16², 16…64 spp, 256-spp reference. Checks beyond "it ran": every level of both integrators and
    scenes is there with finite errors and increasing times; hg_path's mean ΔE₀₀ at 64 spp is below its
    16-spp value (noise ∝ N^(−1/2): ratio ≈ 0.5, or ≈ 0.6 with the 256-spp reference's own noise, over 256
    pixels; the relative RMSE is not used: the mirror scene's caustic fireflies make it heavy-tailed at
    16²); the reference's own error (half that of its halves' difference) is below every level's."""
    results = bench_convergence.main(quick=True, plot_path=tmp_path / "plot.svg")
    assert json.loads(Path(results["path"]).read_text())["levels_spp"] == list(bench_convergence.QUICK_LEVELS)
    assert not (tmp_path / "plot.svg").exists()
    for name in bench_convergence.SCENES:
        scene = results["scenes"][name]
        for integrator in bench_convergence.INTEGRATORS:
            levels = scene[integrator]["levels"]
            assert [level["spp"] for level in levels] == list(bench_convergence.QUICK_LEVELS)
            assert all(math.isfinite(level["delta_e00_p95"]) for level in levels)
            assert all(later["seconds"] > earlier["seconds"] for earlier, later in itertools.pairwise(levels))
            assert all(level["delta_e00_p95"] > scene["reference"]["delta_e00_p95"] for level in levels)
        plt = scene["hg_path"]["levels"]
        assert plt[-1]["delta_e00_mean"] < plt[0]["delta_e00_mean"]


def test_plot_has_a_line_per_scene_and_integrator() -> None:
    """The SVG plot of a results dict: one polyline per scene × integrator per panel."""
    level = {"spp": 16, "seconds": 1.0, "delta_e00_p95": 3.0}
    scenes = {
        name: {
            "reference": {"delta_e00_p95": 0.2},
            **{
                integrator: {"levels": [level, {**level, "spp": 32, "seconds": 2.0, "delta_e00_p95": 2.0}]}
                for integrator in bench_convergence.INTEGRATORS
            },
        }
        for name in bench_convergence.SCENES
    }
    svg = bench_convergence.convergence_svg({"scenes": scenes})
    assert svg.count("<polyline") == 2 * len(bench_convergence.SCENES) * len(bench_convergence.INTEGRATORS)
    assert svg.startswith("<svg") and svg.rstrip().endswith("</svg>")
