"""Fixtures of the deployment tests: the live API and worker subprocesses of the service tests (reused,
not duplicated)."""

from tests.service.conftest import live_service  # noqa: F401  (re-exported pytest fixture)
