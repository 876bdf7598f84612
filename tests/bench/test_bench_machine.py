"""What benchmarks record about the machine (bench/machine.py) and how the kernel profile pairs renders."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.bench_kernel_profile import PAIRED_METRICS, _add_pairs
from bench.machine import cpu_generation, cpu_model, cpu_simd

# Two processors as /proc/cpuinfo lists them; only the first is read (they are alike on these VMs).
CPUINFO = """processor\t: 0
vendor_id\t: AuthenticAMD
cpu family\t: 23
model\t\t: 49
model name\t: AMD EPYC
flags\t\t: fpu sse sse2 sse4_2 avx avx2 fma

processor\t: 1
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 17
model name\t: other
flags\t\t: fpu avx2 avx512f
"""


@pytest.fixture
def cpuinfo(tmp_path: Path) -> Path:
    path = tmp_path / "cpuinfo"
    path.write_text(CPUINFO)
    return path


def test_the_first_processor_names_model_generation_and_widest_vector_extension(cpuinfo: Path) -> None:
    assert cpu_model(cpuinfo) == "AMD EPYC"
    assert cpu_generation(cpuinfo) == "family 23 model 49"
    assert cpu_simd(cpuinfo) == "avx2"  # avx512f is the second processor's, not read


def test_avx512_is_reported_before_avx2(tmp_path: Path) -> None:
    path = tmp_path / "cpuinfo"
    path.write_text("cpu family\t: 25\nmodel\t\t: 17\nflags\t\t: sse4_2 avx avx2 avx512f avx512bw\n")
    assert cpu_simd(path) == "avx512f"
    assert cpu_generation(path) == "family 25 model 17"


def test_an_unreadable_cpuinfo_gives_unknown_not_an_error(tmp_path: Path) -> None:
    missing = tmp_path / "absent"
    assert cpu_generation(missing) == "unknown"
    assert cpu_simd(missing) == "none"


def test_pairs_divide_render_i_by_render_i_of_each_mitsuba_integrator() -> None:
    def record(seconds: float) -> dict[str, float]:
        return dict.fromkeys(PAIRED_METRICS, seconds)

    timed = {
        "hg_path": [record(1.1), record(2.2)],
        "path": [record(1.0), record(2.0)],
        "prb": [record(0.5), record(4.4)],
    }
    paired: dict[str, dict[str, list[float]]] = {}
    _add_pairs(paired, timed)
    _add_pairs(paired, {"hg_path": [record(3.0)], "path": [record(2.0)], "prb": [record(3.0)]})
    assert set(paired) == {"this/path", "this/prb"}
    for metric in PAIRED_METRICS:
        assert paired["this/path"][metric] == pytest.approx([1.1, 1.1, 1.5])
        assert paired["this/prb"][metric] == pytest.approx([2.2, 0.5, 1.0])
