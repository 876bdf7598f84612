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


@pytest.mark.skipif(shutil.which("nvidia-smi") is not None, reason="this machine has nvidia-smi")
def test_gpu_check_without_a_gpu_skips_and_exits_0(tmp_path: Path) -> None:
    results = ROOT / "bench" / "results" / "gpu_check.json"
    before = results.read_bytes() if results.exists() else None
    env = {**os.environ, "PYTHON": sys.executable}
    done = subprocess.run(
        [str(ROOT / "bench" / "gpu_check.sh")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == {"gpu": None, "skipped": "nvidia-smi not found"}
    assert (results.read_bytes() if results.exists() else None) == before


def test_gpu_check_with_a_gpu_listing_none_skips(tmp_path: Path) -> None:
    """A fake ``nvidia-smi`` that lists no GPU (a driver without devices) is a skip too, not a failure."""
    fake = tmp_path / "nvidia-smi"
    fake.write_text("#!/bin/sh\necho 'No devices were found'\nexit 6\n")
    fake.chmod(0o755)
    env = {**os.environ, "PYTHON": sys.executable, "PATH": f"{tmp_path}:{os.environ['PATH']}"}
    done = subprocess.run(
        [str(ROOT / "bench" / "gpu_check.sh")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == {"gpu": None, "skipped": "nvidia-smi lists no GPU"}
