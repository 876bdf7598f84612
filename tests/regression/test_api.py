"""Schedules, runs, baselines and failure webhooks through the HTTP API, with a real queue worker.

The suite is the thin film under a sphere light at 16×16 px, 8 spp, 8 bands (as in test_regress_cli.py):
a re-render with another seed (every run has its own) passes; doubling the light's radius halves the
coherence lengths and fails on coherence drift. Run-now is used instead of waiting for due times (the
scheduler has its own tests).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.live_service import LiveService
from tests.support.regression import SCENE_NAME, RegressionApi, suite
from tests.support.webhooks import Receiver, running_receiver


@pytest.fixture()
def receiver() -> Iterator[Receiver]:
    with running_receiver(failures=1) as hook:  # the first delivery fails: the alert arrives by a retry
        yield hook


def test_runs_pass_on_noise_fail_on_change_alert_and_promote(
    live_service: LiveService, receiver: Any
) -> None:
    live_service.start_worker(HGRENDER_REGRESSION_WEBHOOK_RETRY_INTERVALS_S="[0.2, 0.4]")
    api = RegressionApi(live_service)
    reference = api.post("/v1/schedules", {"name": "ref", "interval_s": 86400, "suite": suite()}, expect=201)

    first = api.run_to_end(reference["id"])
    assert first["status"] == "passed"
    assert first["scenes"][0]["metrics"] == {"baseline_created": 1}  # no baseline yet: this render is v1
    baselines = api.get(f"/v1/baselines/{SCENE_NAME}")
    assert baselines["current"] == 1 and baselines["versions"][0]["job_id"] == first["scenes"][0]["job_id"]

    second = api.run_to_end(reference["id"])
    assert second["status"] == "passed", second["reasons"]
    assert second["scenes"][0]["baseline_version"] == 1
    assert second["scenes"][0]["job_id"] != first["scenes"][0]["job_id"]
    assert second["scenes"][0]["metrics"]["delta_e00"]["p95"] > 0  # noise differs, yet passes

    changed = api.post(
        "/v1/schedules",
        {"name": "bigger light", "interval_s": 86400, "suite": suite(0.012), "webhook_url": receiver.url},
        expect=201,
    )
    failed = api.run_to_end(changed["id"])
    assert failed["status"] == "failed"
    assert any(r.startswith(f"{SCENE_NAME}: coherence_drift of l1_um") for r in failed["reasons"])
    assert failed["webhook"]["delivered"] is True and failed["webhook"]["attempts"] == 2
    assert len(receiver.bodies) == 2 and receiver.bodies[-1]["event"] == "regression.failed"
    assert receiver.bodies[-1]["run"]["id"] == failed["id"]

    history = api.get(f"/v1/schedules/{changed['id']}/runs")
    assert [run["id"] for run in history["items"]] == [failed["id"]]
    assert history["series"][SCENE_NAME][0]["verdict"] == "fail"
    assert history["series"][SCENE_NAME][0]["baseline_job_id"] == first["scenes"][0]["job_id"]

    promoted = api.post("/v1/baselines", {"run_id": failed["id"]}, expect=201)
    assert [(b["scene"], b["version"]) for b in promoted] == [(SCENE_NAME, 2)]
    after = api.run_to_end(changed["id"])
    assert after["status"] == "passed" and after["scenes"][0]["baseline_version"] == 2
    # Roll back: the reference schedule's scene compares with v1 again.
    api.post(f"/v1/baselines/{SCENE_NAME}/current?version=1")
    assert api.get(f"/v1/baselines/{SCENE_NAME}")["current"] == 1


def test_schedule_lifecycle_and_validation(live_service: LiveService) -> None:
    api = RegressionApi(live_service)
    created = api.post(
        "/v1/schedules",
        {"name": "nightly", "cron": "0 2 * * *", "timezone": "Europe/Berlin", "suite": suite()},
        expect=201,
    )
    assert api.get(f"/v1/schedules/{created['id']}")["timezone"] == "Europe/Berlin"
    assert api.post(f"/v1/schedules/{created['id']}/pause")["paused"] is True
    assert api.post(f"/v1/schedules/{created['id']}/resume")["paused"] is False
    assert created["id"] in [s["id"] for s in api.get("/v1/schedules")["items"]]
    assert api.http.delete(f"/v1/schedules/{created['id']}").status_code == 204
    api.get(f"/v1/schedules/{created['id']}", expect=404)

    for body, field in (
        ({"name": "x", "cron": "every day", "suite": suite()}, "cron"),
        ({"name": "x", "cron": "0 2 * * *", "interval_s": 60, "suite": suite()}, "cron"),
        ({"name": "x", "interval_s": 60, "timezone": "Mars/Olympus", "suite": suite()}, "timezone"),
        ({"name": "x", "interval_s": 60, "suite": {"scenes": []}}, "scenes"),
        ({"name": "x", "interval_s": 60, "suite": {"scenes": [{"example": "no_such_scene"}]}}, "example"),
        ({"name": "x", "interval_s": 60, "suite": {"scenes": [{"example": "cornell_box", "spp": 0}]}}, "spp"),
    ):
        response = api.http.post("/v1/schedules", json=body)
        assert response.status_code == 422 and field in response.text, (body, response.text)


def test_a_scene_that_cannot_render_is_refused_at_creation(live_service: LiveService) -> None:
    api = RegressionApi(live_service)
    broken = suite()
    broken["scenes"][0]["scene"]["emitters"][0]["radius_m"] = -1.0
    response = api.http.post("/v1/schedules", json={"name": "broken", "interval_s": 60, "suite": broken})
    assert response.status_code == 422 and "/emitters/0/radius_m" in response.text, response.text


def test_other_owners_cannot_see_schedules(live_service: LiveService) -> None:
    api = RegressionApi(live_service)
    created = api.post(
        "/v1/schedules", {"name": "private", "interval_s": 86400, "suite": suite()}, expect=201
    )
    token = live_service.new_token("mallory")
    response = httpx.get(
        f"{live_service.base_url}/v1/schedules/{created['id']}",
        headers={"Authorization": f"Bearer {token}"},
        timeout=30,
    )
    assert response.status_code == 404
    listing = httpx.get(
        f"{live_service.base_url}/v1/schedules", headers={"Authorization": f"Bearer {token}"}, timeout=30
    )
    assert created["id"] not in [s["id"] for s in listing.json()["items"]]


def test_regress_cli_against_the_service(
    live_service: LiveService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from hgrender.cli import main

    live_service.start_worker()
    reference, changed = tmp_path / "suite.json", tmp_path / "changed.json"
    for path, radius_m in ((reference, 0.006), (changed, 0.012)):
        body = suite(radius_m)
        body["scenes"][0]["name"] = "cli_thin_film"
        path.write_text(json.dumps(body))
    common = ["--url", live_service.base_url, "--token", live_service.admin_token, "--timeout-s", "120"]
    # No baseline yet: the first run creates v1; --update-baseline promotes the run again (v2).
    assert main(["regress", str(reference), *common, "--update-baseline"]) == 0
    assert RegressionApi(live_service).get("/v1/baselines/cli_thin_film")["current"] == 2
    capsys.readouterr()
    assert main(["regress", str(reference), *common]) == 0
    assert f"{'cli_thin_film':<28} pass" in capsys.readouterr().out
    junit = tmp_path / "report.xml"
    assert main(["regress", str(changed), *common, "--junit", str(junit)]) == 1
    assert "cli_thin_film: coherence_drift of l1_um" in capsys.readouterr().out
    assert 'failures="1"' in junit.read_text()
    assert main(["regress", str(reference), *common, "--seed", "3"]) == 2  # local-only option
