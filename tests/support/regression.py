"""Driving regression schedules and runs over the HTTP API: the suite the tests use (the thin film under a
sphere light at 16×16 px, 8 spp, 8 bands) and an admin client that waits for runs."""

from __future__ import annotations

from typing import Any

import httpx

from tests.support.live_service import LiveService
from tests.support.processes import wait_for
from tests.support.scenes import example

SCENE_NAME = "thin_film"


def suite(light_radius_m: float = 0.006) -> dict[str, Any]:
    """One scene, its light of radius ``light_radius_m`` (a larger one shortens the coherence lengths)."""
    scene = example("thin_film_sphere_light", bands=8)
    scene["emitters"][0]["radius_m"] = light_radius_m
    return {"scenes": [{"name": SCENE_NAME, "scene": scene, "spp": 8, "width": 16, "height": 16}]}


class RegressionApi:
    """The admin's HTTP client of the regression endpoints, asserting each status code."""

    def __init__(self, service: LiveService) -> None:
        self.http = httpx.Client(
            base_url=service.base_url, headers={"Authorization": f"Bearer {service.admin_token}"}, timeout=30
        )

    def post(self, path: str, body: Any = None, expect: int = 200) -> Any:
        response = self.http.post(path, json=body if body is not None else {})
        assert response.status_code == expect, response.text
        return response.json() if response.content else None

    def get(self, path: str, expect: int = 200) -> Any:
        response = self.http.get(path)
        assert response.status_code == expect, response.text
        return response.json()

    def run_to_end(self, schedule_id: str) -> dict[str, Any]:
        run = self.post(f"/v1/schedules/{schedule_id}/run", expect=202)
        assert run["status"] == "running" and run["trigger"] == "manual"
        return wait_for(
            lambda: (r := self.get(f"/v1/runs/{run['id']}"))["status"] != "running" and r,
            120,
            f"run {run['id']} to finish",
            interval_s=0.3,
        )
