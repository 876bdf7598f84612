"""``bench/gpu_check.sh`` on a machine without an NVIDIA GPU: it says so, renders nothing, writes no
results and exits 0 (the GPU path itself runs only where a GPU is lent; see the notes of issue 16)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results" / "gpu_check.json"


def run_gpu_check(path_prefix: Path | None = None) -> dict:
    """bench/gpu_check.sh's JSON output; it must exit 0 and leave the results file as it was."""
    before = RESULTS.read_bytes() if RESULTS.exists() else None
    env = {**os.environ, "PYTHON": sys.executable}
    if path_prefix is not None:
        env["PATH"] = f"{path_prefix}:{env['PATH']}"
    command = [str(ROOT / "bench" / "gpu_check.sh")]
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert (RESULTS.read_bytes() if RESULTS.exists() else None) == before
    return json.loads(done.stdout)


@pytest.mark.skipif(shutil.which("nvidia-smi") is not None, reason="this machine has nvidia-smi")
def test_gpu_check_without_a_gpu_skips_and_exits_0() -> None:
    assert run_gpu_check() == {"gpu": None, "skipped": "nvidia-smi not found"}


def test_gpu_check_with_a_gpu_listing_none_skips(tmp_path: Path) -> None:
    """A fake ``nvidia-smi`` that lists no GPU (a driver without devices) is a skip too, not a failure."""
    fake = tmp_path / "nvidia-smi"
    fake.write_text("#!/bin/sh\necho 'No devices were found'\nexit 6\n")
    fake.chmod(0o755)
    assert run_gpu_check(tmp_path) == {"gpu": None, "skipped": "nvidia-smi lists no GPU"}
