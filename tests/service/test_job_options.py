"""Job options over HTTP: ``integrator`` (overrides ``film.integrator``) and the noise target
(``target_rel_error``, ``time_budget_s``, ``target_quantile``): validation, the job view, and what a
worker renders for them (summary.json, the achieved error in the view and the manifest)."""

from __future__ import annotations

import itertools
import json
import time
from pathlib import Path

import pytest

from tests.support.live_service import LiveService
from tests.support.scenes import tiny_scene


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
    client = live_service.client(live_service.new_token("olga"))
    before = client.list()["total"]
    response = client.http.post("/v1/jobs", json={"scene": tiny_scene(), **options})
    assert response.status_code == 422
    assert field in response.json()["detail"]
    assert client.list()["total"] == before


def test_options_are_recorded_in_the_view(live_service: LiveService) -> None:
    client = live_service.client(live_service.new_token("olga"))
    job = client.submit(tiny_scene(spp=4), target_rel_error=0.05, target_quantile=0.9, integrator="rlt")
    view = client.get(job["id"])
    assert view["chunks_total"] == 1  # the server's default is 2 chunks; a target job renders as one
    assert view["noise_target"]["target_rel_error"] == 0.05
    assert view["noise_target"]["target_quantile"] == 0.9
    assert view["noise_target"]["achieved_rel_error"] is None  # not rendered yet
    fixed = client.submit(tiny_scene())["id"]
    assert client.get(fixed)["noise_target"] is None
    # The integrator is written into the stored scene (what the worker renders).
    scene = live_service.jobs.scene(job["id"])
    assert scene["film"]["integrator"] == "rlt"
    for job_id in (job["id"], fixed):  # no worker of a later test may find them queued
        client.cancel(job_id)


def test_a_worker_renders_the_integrator_and_meets_the_noise_target(
    live_service: LiveService, tmp_path: Path
) -> None:
    client = live_service.client(live_service.new_token("olga"))
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


def test_a_noise_target_job_publishes_its_image_after_each_round_while_it_runs(
    live_service: LiveService, tmp_path: Path
) -> None:
    """Issue 16 item 4: the viewer's preview of a running target job is the image of the rounds so far.
    A 0.5 % band-mean target on a 16² Cornell box from 2 spp needs ~10⁴ spp (the error falls as 1/√N),
    in rounds of 2, 18, 162, 1458, … spp (8× growth cap). The job's event stream sends the view after
    each published round (the first always; later ones once the render since outlasts 10× the last
    publication: here at least the 1458-spp round's), and the preview is read over HTTP right then."""
    token = live_service.new_token("pia")
    client = live_service.client(token)
    job_id = client.submit(tiny_scene(spp=2), target_rel_error=0.005)["id"]
    observed: dict[int, float] = {}  # round count → achieved error the running job's view showed
    previews: list[tuple[int, int]] = []  # (rounds seen in the view, spp of the preview served)
    events = client.events(job_id, deadline=time.monotonic() + 240)
    try:
        next(events)  # the stream is open (the first view): no round published from now on is missed
        live_service.start_worker("rounds")
        for event, view in events:
            if event != "status" or view["status"] != "running":
                continue
            block = view["noise_target"]
            rounds = block.get("rounds") or []
            if rounds:
                assert block["stop_reason"] is None and block["spp"] == rounds[-1]["spp"]
                observed[len(rounds)] = block["achieved_rel_error"]
                layers = live_service.get(f"/v1/jobs/{job_id}/layers", token=token)
                if layers.status_code == 200 and layers.json()["partial"]:
                    previews.append((len(rounds), layers.json()["spp"]))
        final = client.get(job_id)
    finally:
        events.close()
        live_service.stop_workers()
    assert final["status"] == "succeeded", final.get("error")
    result = final["noise_target"]
    assert result["met"] and result["stop_reason"] == "target_met"
    round_errors = [r["rel_error"] for r in result["rounds"]]
    round_spp = [r["spp"] for r in result["rounds"]]
    # Every running view showed the error of the rounds finished so far, and it fell round by round.
    assert len(observed) >= 2, (observed, round_spp)
    for count, error in observed.items():
        assert error == round_errors[count - 1]
    seen = [observed[count] for count in sorted(observed)]
    assert all(later < earlier for earlier, later in itertools.pairwise(seen)), seen
    # The preview served while running was a round's image (a later one than the view may say: the
    # partial is replaced before the view's block), never the final one.
    assert previews, "no preview was served while the job ran"
    for count, spp in previews:
        assert spp in round_spp[count - 1 : -1], (count, spp, round_spp)
    # Once succeeded, the final image replaces it; the rounds' partial is gone from the artifacts.
    done = live_service.get(f"/v1/jobs/{job_id}/layers", token=token).json()
    assert done["partial"] is False and done["spp"] is None
    client.download(job_id, "manifest.json", tmp_path / "manifest.json")
    names = [a["name"] for a in json.loads((tmp_path / "manifest.json").read_text())["artifacts"]]
    assert not [name for name in names if name.startswith("chunks/")], names
