"""What every benchmark records about the machine it ran on, and where it writes its results.

The machines these benchmarks run on are shared virtual machines whose speed drifts with the host's load
(by up to 2x within an hour on the 2-core development VM). Every result therefore carries
``cpu_reference_s``: the time of a fixed single-threaded Python workload, measured with the benchmark.
Compare figures across runs only where it is similar; compare versions within one run (or session).
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hgcore.artifacts.images import atomic_write_bytes

RESULTS_DIR = Path(__file__).resolve().parent / "results"
REFERENCE_ITERATIONS = 2_000_000
CPUINFO = Path("/proc/cpuinfo")


SIMD_EXTENSIONS = ("avx512f", "avx2", "avx", "sse4_2")
"""x86 vector extensions, widest first: Dr.Jit's LLVM backend traces 16-lane packets with AVX-512 and
8-lane ones with AVX2, which changes how often a packet can skip a symbolic branch, so ratios between
integrators measured on one ISA need not hold on another."""


def _cpuinfo_fields(cpuinfo: Path) -> dict[str, str]:
    """The first processor's ``key: value`` lines of ``cpuinfo`` (empty where it cannot be read)."""
    fields: dict[str, str] = {}
    try:
        text = cpuinfo.read_text(encoding="utf-8")
    except OSError:
        return fields
    for line in text.split("\n\n", 1)[0].splitlines():
        key, _, value = line.partition(":")
        fields[key.strip()] = value.strip()
    return fields


def cpu_model(cpuinfo: Path = CPUINFO) -> str:
    """The CPU model name from /proc/cpuinfo (Linux), else the platform's processor string."""
    return _cpuinfo_fields(cpuinfo).get("model name") or platform.processor() or "unknown"


def cpu_generation(cpuinfo: Path = CPUINFO) -> str:
    """``family F model M`` from /proc/cpuinfo: virtual machines often name only the vendor's line
    ("AMD EPYC"), which hides the generation (family 23 model 49 is Zen 2)."""
    fields = _cpuinfo_fields(cpuinfo)
    if "cpu family" not in fields:
        return "unknown"
    return f"family {fields['cpu family']} model {fields.get('model', '?')}"


def cpu_simd(cpuinfo: Path = CPUINFO) -> str:
    """The widest of ``SIMD_EXTENSIONS`` the CPU reports, or "none"."""
    flags = set(_cpuinfo_fields(cpuinfo).get("flags", "").split())
    return next((name for name in SIMD_EXTENSIONS if name in flags), "none")


def cpu_reference_s(repeats: int = 3) -> float:
    """Seconds for a fixed pure-Python loop (``REFERENCE_ITERATIONS`` additions), best of ``repeats``."""
    best_s = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        total = 0
        for value in range(REFERENCE_ITERATIONS):
            total += value
        best_s = min(best_s, time.perf_counter() - start)
    return best_s


def write_results(name: str, results: dict[str, Any]) -> Path:
    """Write ``results`` to ``bench/results/<name>.json`` (atomically) and return the path."""
    path = RESULTS_DIR / f"{name}.json"
    atomic_write_bytes(path, (json.dumps(results, indent=2) + "\n").encode())
    return path


class MachineLoad:
    """The machine's speed and load around a benchmark: ``cpu_reference_s`` and the load average when
    created (before) and when ``fields`` is called (after), with the CPU model, generation, vector
    extension and count."""

    def __init__(self) -> None:
        self.reference_before_s = cpu_reference_s()
        self.load_before = os.getloadavg()

    def fields(self) -> dict[str, Any]:
        return {
            "cpu_model": cpu_model(),
            "cpu_generation": cpu_generation(),
            "cpu_simd": cpu_simd(),
            "cpu_count": os.cpu_count(),
            "cpu_reference_s": {"before": self.reference_before_s, "after": cpu_reference_s()},
            "loadavg": {"before": self.load_before, "after": os.getloadavg()},
        }


def paired_ratio(
    baseline: Callable[[int], None], candidate: Callable[[int], None], rounds: int, goal: float
) -> dict[str, Any]:
    """CPU and wall seconds of ``candidate(seed)`` over ``baseline(seed)``, alternated for ``rounds`` rounds
    with the order reversed every round (A B B A …: drift on these VMs cancels), after one warm-up call each
    (kernels compiled). ``paired_ratio_cpu`` is the median of the per-round ratios (CPU time: robust to the
    machine's other users); ``met`` whether it is at most ``goal``."""

    def timed(render: Callable[[int], None], seed: int) -> tuple[float, float]:
        cpu, wall = time.process_time(), time.perf_counter()
        render(seed)
        return time.process_time() - cpu, time.perf_counter() - wall

    timed(baseline, 0), timed(candidate, 0)
    ratios_cpu, ratios_wall = [], []
    times: dict[str, list[tuple[float, float]]] = {"baseline": [], "candidate": []}
    for round_index in range(rounds):
        order = ("baseline", "candidate") if round_index % 2 == 0 else ("candidate", "baseline")
        measured = {}
        for name in order:
            measured[name] = timed(baseline if name == "baseline" else candidate, round_index + 1)
            times[name].append(measured[name])
        ratios_cpu.append(measured["candidate"][0] / measured["baseline"][0])
        ratios_wall.append(measured["candidate"][1] / measured["baseline"][1])
    return {
        "baseline_cpu_s": statistics.median(t[0] for t in times["baseline"]),
        "candidate_cpu_s": statistics.median(t[0] for t in times["candidate"]),
        "paired_ratio_cpu": statistics.median(ratios_cpu),
        "paired_ratio_wall": statistics.median(ratios_wall),
        "ratios_cpu": ratios_cpu,
        "goal": goal,
        "met": statistics.median(ratios_cpu) <= goal,
    }
