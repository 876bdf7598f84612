"""Interpolation error of the open-cylinder mode table (``sources.open_cylinder_coefficient_table``).

The kernels interpolate ĉ_nm(α) linearly between ``samples`` uniform nodes α ∈ [0, π/2]. A table with
2·samples − 1 nodes holds the exact-integration coefficients at every midpoint of the coarse one, where
linear interpolation errs most (error ≈ h²/8 · |ĉ''|); this compares the two for each mode count of a
film (1–16) and reports max |Δĉ_nm| and max Σ_nm |Δĉ_nm| (|Δμ| ≤ Σ|Δĉ|/√π, Cramér's |h_n| ≤ π^{-1/4}),
with where (α, deg) they occur, for the table's resolution and half of it. Results: stdout and
``bench/results/cylinder_modes.json``. ~15 s of exact integration (0.04 s per node).
"""

from __future__ import annotations

import json
import math
import sys
from typing import Any

import numpy as np

from bench.machine import write_results
from hgcore.optics.sources import (
    OPEN_CYLINDER_TABLE_SAMPLES,
    open_cylinder_coefficient_table,
    open_cylinder_table_obliquities,
)
from schemas.scene import MAX_FILM_MODES


def midpoint_errors(samples: int) -> dict[str, Any]:
    """Max over mode counts 1..MAX_FILM_MODES, labels and midpoints of |Δĉ| and of Σ|Δĉ| at ``samples``."""
    fine_alpha = open_cylinder_table_obliquities(2 * samples - 1)
    worst = {"max_abs": 0.0, "max_sum_abs": 0.0, "max_abs_at_deg": 0.0, "max_sum_abs_at_deg": 0.0}
    for mode_count in range(1, MAX_FILM_MODES + 1):
        _, coarse = open_cylinder_coefficient_table(mode_count, samples)
        _, fine = open_cylinder_coefficient_table(mode_count, 2 * samples - 1)
        interpolated = 0.5 * (coarse[:-1] + coarse[1:])
        error = np.abs(interpolated - fine[1::2])  # [midpoint, label, mode]
        at = fine_alpha[1::2]
        per_point = error.max(axis=(1, 2))
        sums = error.sum(axis=2).max(axis=1)
        if per_point.max() > worst["max_abs"]:
            worst["max_abs"] = float(per_point.max())
            worst["max_abs_at_deg"] = math.degrees(at[per_point.argmax()])
        if sums.max() > worst["max_sum_abs"]:
            worst["max_sum_abs"] = float(sums.max())
            worst["max_sum_abs_at_deg"] = math.degrees(at[sums.argmax()])
    worst["mu_bound"] = worst["max_sum_abs"] / math.sqrt(math.pi)
    return worst


def main() -> dict[str, Any]:
    results = {
        f"samples_{samples}": midpoint_errors(samples)
        for samples in (OPEN_CYLINDER_TABLE_SAMPLES, (OPEN_CYLINDER_TABLE_SAMPLES + 1) // 2)
    }
    write_results("cylinder_modes", results)
    return results


if __name__ == "__main__":
    json.dump(main(), sys.stdout, indent=2)
    sys.stdout.write("\n")
