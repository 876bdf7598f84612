"""Helpers shared by the test modules (``tests/README.md``): plain modules that tests import. Fixtures live
in ``conftest.py`` files, which no module imports; no test module imports another."""

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
"""The repository's root folder."""
