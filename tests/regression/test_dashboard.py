"""The regression dashboard (``web/regression/``) in headless Chromium (Debian's ``/usr/bin/chromium``
driven by Playwright) against a live API and a real worker: the schedules table, a schedule's runs with
the ΔE₀₀ p95 trend plot (a passing run is a filled dot, a failing one a ring), and a failing scene's
baseline against its current render in the viewer's compare view.
Screenshot: test-artifacts/regression-dashboard.png."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.regression.test_api import Client, suite
from tests.service.conftest import LiveService
from tests.web.conftest import screenshot

pytestmark = pytest.mark.browser


@pytest.fixture()
def page(live_service: LiveService, chromium: Any) -> Iterator[Any]:
    """A page on the session's shared headless Chromium (tests/conftest.py) with the admin token set."""
    context = chromium.new_context(viewport={"width": 1280, "height": 900})
    context.add_init_script(f"window.localStorage.setItem('hgrender.token', {live_service.admin_token!r});")
    page = context.new_page()
    page.set_default_timeout(60_000)  # the test machine's 2 cores are shared: allow slow renders of the page
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        yield page
    finally:
        context.close()
    assert not errors, errors


def test_dashboard_shows_schedules_trend_and_compare(live_service: LiveService, page: Any) -> None:
    live_service.start_worker()
    api = Client(live_service)
    reference = api.post(
        "/v1/schedules", {"name": "reference", "interval_s": 86400, "suite": suite()}, expect=201
    )
    changed = api.post(
        "/v1/schedules", {"name": "bigger light", "interval_s": 86400, "suite": suite(0.012)}, expect=201
    )
    baseline_run = api.run_to_end(reference["id"])
    passing_run = api.run_to_end(reference["id"])
    failing_run = api.run_to_end(changed["id"])
    assert (baseline_run["status"], passing_run["status"], failing_run["status"]) == (
        "passed",
        "passed",
        "failed",
    )

    page.goto(f"{live_service.base_url}/web/regression/index.html")
    rows = page.locator("#schedules tbody tr")
    rows.first.wait_for()
    assert rows.count() == 2
    assert "every 86400 s" in page.locator("#schedules").inner_text()

    # The reference schedule: two runs, the second compared (a filled dot on the trend plot).
    page.get_by_role("button", name="reference").click()
    page.locator("#runs tbody tr").nth(1).wait_for()
    assert page.locator("#runs tbody tr").count() == 2
    assert page.locator("#trend circle").count() == 1
    assert page.locator("#trend circle").get_attribute("fill") != "none"

    # The failing schedule: a ring on the plot, the reason in the table, and the compare view.
    page.get_by_role("button", name="bigger light").click()
    page.locator("#runs tbody tr td.run-status-failed").wait_for()
    assert page.locator("#trend circle").get_attribute("fill") == "none"
    assert "thin_film: coherence_drift of l1_um" in page.locator("#runs").inner_text()
    page.locator("#runs button.verdict-fail").click()
    # The dashboard opens the compare view on its ΔE₀₀ map: wait until it has drawn, then for that map.
    page.wait_for_function("() => Number(document.querySelector('#compare .compare')?.dataset.ready) >= 1")
    page.locator("#compare section.compare canvas.compare-diff").wait_for()
    caption = page.locator("#compare-caption").inner_text()
    assert baseline_run["scenes"][0]["job_id"] in caption and failing_run["scenes"][0]["job_id"] in caption
    screenshot(page, "regression-dashboard")
