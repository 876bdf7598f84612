"""Run every ``bench/bench_*.py`` module's ``main() -> dict`` and print one JSON object keyed by module."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path


def run_all() -> dict[str, object]:
    """Import each benchmark module in name order and collect its ``main()`` result."""
    results: dict[str, object] = {}
    for path in sorted(Path(__file__).resolve().parent.glob("bench_*.py")):
        module = importlib.import_module(f"bench.{path.stem}")
        results[path.stem] = module.main()
    return results


if __name__ == "__main__":
    json.dump(run_all(), sys.stdout, indent=2)
    sys.stdout.write("\n")
