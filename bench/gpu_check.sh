#!/usr/bin/env bash
# GPU readiness check (issue 16, item 6): bench/gpu_check.py under a 5-minute limit, from the repository
# root with its virtual environment. Exits 0 and prints {"gpu": null, "skipped": ...} on a machine
# without an NVIDIA GPU; otherwise renders the Cornell box and a thin-film scene on CPU and GPU, writes
# bench/results/gpu_check.json and exits 1 if the GPU disagrees with the CPU beyond Monte Carlo error.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-.venv/bin/python}"
exec timeout "${GPU_CHECK_TIMEOUT_S:-300}" env PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" "$PYTHON" -m bench.gpu_check
