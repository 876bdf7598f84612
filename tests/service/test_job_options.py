"""Job options over HTTP: ``integrator`` (overrides ``film.integrator``) and the noise target
(``target_rel_error``, ``time_budget_s``, ``target_quantile``): validation, the job view, and what a
worker renders for them (summary.json, the achieved error in the view and the manifest)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.service.conftest import LiveService, tiny_scene


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"integrator": "path"}, "integrator"),
        ({"target_rel_error": 0}, "target_rel_error"),
        ({"target_rel_error": 2.0}, "target_rel_error"),
        ({"time_budget_s": -1}, "time_budget_s"),
        ({"target_quantile": 0.5}, "target_quantile"),  # a quantile of what target?
        ({"target_quantile": 1.5, "target_rel_error": 0.1}, "target_quantile"),
        ({"target_rel_error": 0.1, "chunks": 4}, "chunks"),  # a target job is one chunk
        ({"target_rel_error": "0.1"}, "target_rel_error"),  # strict JSON types, like spp
    ],
)
def test_bad_options_are_422_naming_the_field_and_nothing_is_enqueued(
    live_service: LiveService, options: dict, field: str
) -> None:
    client = live_service.client(live_service.token("olga"))
    before = client.list()["total"]
    response = client.http.post("/v1/jobs", json={"scene": tiny_scene(), **options})
    assert response.status_code == 422
    assert field in response.json()["detail"]
    assert client.list()["total"] == before


def test_options_are_recorded_in_the_view(live_service: LiveService) -> None:
    client = live_service.client(live_service.token("olga"))
    job = client.submit(tiny_scene(spp=4), target_rel_error=0.05, target_quantile=0.9, integrator="rlt")
    view = client.get(job["id"])
    assert view["chunks_total"] == 1  # the server's default is 2 chunks; a target job renders as one
    assert view["noise_target"]["target_rel_error"] == 0.05
    assert view["noise_target"]["target_quantile"] == 0.9
    assert view["noise_target"]["achieved_rel_error"] is None  # not rendered yet
    fixed = client.submit(tiny_scene())["id"]
    assert client.get(fixed)["noise_target"] is None
    # The integrator is written into the stored scene (what the worker renders).
    scene = json.loads(live_service.redis.get(f"hgrender:job:{job['id']}:scene"))
    assert scene["film"]["integrator"] == "rlt"
    for job_id in (job["id"], fixed):  # no worker of a later test may find them queued
        client.cancel(job_id)


def test_a_worker_renders_the_integrator_and_meets_the_noise_target(
    live_service: LiveService, tmp_path: Path
) -> None:
    client = live_service.client(live_service.token("olga"))
    rlt = client.submit(tiny_scene(spp=2), integrator="rlt")["id"]
    target = client.submit(tiny_scene(spp=2), target_rel_error=0.05)["id"]
    live_service.start_worker("options")
    try:
        for job_id in (rlt, target):
            final = client.wait(job_id, timeout_s=120)
            assert final["status"] == "succeeded", final.get("error")
    finally:
        live_service.stop_workers()
    client.download(rlt, "summary.json", tmp_path / "rlt.json")
    assert json.loads((tmp_path / "rlt.json").read_text())["integrator"] == "rlt"
    view = client.get(target)
    achieved = view["noise_target"]
    assert (
        achieved["met"] and achieved["achieved_rel_error"] <= 0.05 and achieved["stop_reason"] == "target_met"
    )
    assert achieved["spp"] > 2 and len(achieved["band_rel_error"]) == tiny_scene()["film"]["bands"]
    client.download(target, "summary.json", tmp_path / "target.json")
    summary = json.loads((tmp_path / "target.json").read_text())
    assert summary["noise_target"]["achieved_rel_error"] == achieved["achieved_rel_error"]
    assert summary["spp"] == achieved["spp"]
    client.download(target, "manifest.json", tmp_path / "manifest.json")
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["job"]["noise_target"]["met"] is True
