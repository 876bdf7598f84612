"""Fixtures of the regression tests: the service tests' live API and workers (real Redis, real workers)."""

from __future__ import annotations

from tests.service.conftest import live_service  # noqa: F401  (re-exported fixture)
