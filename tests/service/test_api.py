"""API contract without workers: auth and owner visibility, limits, validation, listing, idempotency,
tokens, health, metrics, schema and coherence endpoints — over HTTP against a live server and real Redis.
"""

from __future__ import annotations

import json
import math
import re
import time

import httpx
import pytest

from service.auth import TokenRegistry
from service.rate_limit import counter_key
from tests.support.live_service import LiveService
from tests.support.scenes import tiny_scene


def test_missing_and_invalid_tokens_are_401(live_service: LiveService) -> None:
    assert live_service.get("/v1/jobs", token="").status_code == 401
    response = live_service.get("/v1/jobs", token="hgr_not-a-real-token")
    assert response.status_code == 401
    assert response.json()["detail"].startswith("authorization:")
    assert response.headers["www-authenticate"] == "Bearer"
    assert live_service.get("/v1/jobs", token="garbage").status_code == 401


def test_owner_visibility_and_scopes(live_service: LiveService) -> None:
    alice = live_service.client(live_service.new_token("alice"))
    bob = live_service.client(live_service.new_token("bob"))
    reader = live_service.client(live_service.new_token("carol", ("read",)))
    job = alice.submit(tiny_scene(), chunks=1)
    assert alice.get(job["id"])["owner"] == "alice"
    # Bob can neither see nor cancel nor delete nor download Alice's job: indistinguishable from missing.
    for call in (
        lambda: bob.get(job["id"]),
        lambda: bob.cancel(job["id"]),
        lambda: bob.delete(job["id"]),
        lambda: bob.artifacts(job["id"]),
    ):
        with pytest.raises(Exception) as error:
            call()
        assert getattr(error.value, "status_code", None) == 404
    assert job["id"] not in [j["id"] for j in bob.list()["items"]]
    # Admins see everyone's jobs; a read-only token cannot submit.
    assert job["id"] in [j["id"] for j in live_service.client().list()["items"]]
    with pytest.raises(Exception) as error:
        reader.submit(tiny_scene())
    assert getattr(error.value, "status_code", None) == 403
    # Cancel of a queued job is immediate and final; a second cancel is idempotent.
    assert alice.cancel(job["id"])["status"] == "canceled"
    assert alice.cancel(job["id"])["status"] == "canceled"


def test_oversize_body_is_413_and_nothing_is_enqueued(live_service: LiveService) -> None:
    token = live_service.new_token("big")
    queued_before = live_service.redis.llen("rq:queue:default")
    padding = "x" * (live_service.settings.max_request_bytes + 10)
    response = httpx.post(
        live_service.base_url + "/v1/jobs",
        json={"scene": tiny_scene(), "name": padding},
        headers={"Authorization": f"Bearer {token}"},
        timeout=30,
    )
    assert response.status_code == 413
    assert response.json()["detail"].startswith("body:")
    # Chunked upload without Content-Length is counted too.
    body = (b'{"scene": {}, "name": "' + padding.encode() + b'"}' for _ in range(1))
    response = httpx.post(
        live_service.base_url + "/v1/jobs",
        content=body,
        headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"},
        timeout=30,
    )
    assert response.status_code == 413
    assert live_service.redis.llen("rq:queue:default") == queued_before


def test_malformed_scene_is_422_naming_the_field_and_nothing_is_written(live_service: LiveService) -> None:
    client = live_service.client(live_service.new_token("dave"))
    store_root = live_service.settings.artifact_dir
    before = sorted(store_root.rglob("*")) if store_root.exists() else []
    scene = tiny_scene()
    scene["film"]["spp"] = 0
    response = client.http.post("/v1/jobs", json={"scene": scene})
    assert response.status_code == 422
    body = response.json()
    assert body["detail"].startswith("scene: /film/spp:")
    assert {"pointer": "/film/spp"}.items() <= body["errors"][0].items()
    # Request fields are named too.
    response = client.http.post("/v1/jobs", json={"scene": tiny_scene(), "priority": "urgent"})
    assert response.status_code == 422 and response.json()["detail"].startswith("priority:")
    response = client.http.post("/v1/jobs", json={"scene": tiny_scene(), "chunks": 10_000})
    assert response.status_code == 422 and response.json()["detail"].startswith("chunks:")
    response = client.http.post(
        "/v1/jobs", content=b"{not json", headers={"Content-Type": "application/json"}
    )
    assert response.status_code == 422
    # A JSON scene has no bundle to read a texture from: refused up front, naming the texture's path.
    textured = tiny_scene()
    material = next(iter(textured["materials"]))
    textured["materials"][material] = {"type": "diffuse", "reflectance": {"type": "image", "path": "a.png"}}
    response = client.http.post("/v1/jobs", json={"scene": textured})
    assert response.status_code == 422
    assert response.json()["detail"].startswith(
        f"scene: /materials/{material}/reflectance/path: image 'a.png'"
    )
    after = sorted(store_root.rglob("*")) if store_root.exists() else []
    assert after == before
    assert client.list()["total"] == 0


def test_spp_override_is_validated_against_scene_limits(live_service: LiveService) -> None:
    client = live_service.client(live_service.new_token("erin"))
    response = client.http.post("/v1/jobs", json={"scene": tiny_scene(), "spp": 10_000_000})
    assert response.status_code == 422
    assert response.json()["detail"].startswith("spp:") or "/film/spp" in response.json()["detail"]
    job = client.submit(tiny_scene(spp=4), spp=3, chunks=8)
    view = client.get(job["id"])
    # 8 chunks requested but only 3 samples per pixel: one sample per chunk at least.
    assert (view["spp"], view["chunks_total"], view["status"]) == (3, 3, "queued")
    assert live_service.redis.exists(f"rq:job:{job['id']}-chunk-2", f"rq:job:{job['id']}-merge") == 2


def test_idempotency_key_returns_the_first_job(live_service: LiveService) -> None:
    client = live_service.client(live_service.new_token("frank"))
    first = client.http.post("/v1/jobs", json={"scene": tiny_scene(), "idempotency_key": "nightly-1"})
    second = client.http.post("/v1/jobs", json={"scene": tiny_scene(), "idempotency_key": "nightly-1"})
    assert (first.status_code, second.status_code) == (202, 200)
    assert first.json()["id"] == second.json()["id"]


def test_concurrent_requests_with_one_idempotency_key_make_one_job(live_service: LiveService) -> None:
    from concurrent.futures import ThreadPoolExecutor

    token = live_service.new_token("fiona")

    def submit(_: int) -> str:
        with live_service.client(token) as client:
            return client.submit(tiny_scene(), chunks=1, idempotency_key="race-1")["id"]

    with ThreadPoolExecutor(8) as pool:
        ids = set(pool.map(submit, range(8)))
    assert len(ids) == 1
    assert live_service.client(token).list()["total"] == 1


def test_listing_filters_and_paginates(live_service: LiveService) -> None:
    client = live_service.client(live_service.new_token("gina"))
    ids = [client.submit(tiny_scene(), chunks=1)["id"] for _ in range(5)]
    client.cancel(ids[0])
    page = client.list(limit=2)
    assert page["total"] == 5 and [j["id"] for j in page["items"]] == ids[::-1][:2]
    page = client.list(limit=2, offset=4)
    assert [j["id"] for j in page["items"]] == [ids[0]]
    assert [j["id"] for j in client.list(status="canceled")["items"]] == [ids[0]]
    assert client.list(status="queued")["total"] == 4
    # Missing artifacts and escapes from the job's folder are 404s.
    for name in ("image.exr", "..%2F..%2Fadmin.token", "chunks/../../x"):
        response = client.http.get(f"/v1/jobs/{ids[2]}/artifacts/{name}")
        assert response.status_code == 404, name
    # Delete removes record and artifacts.
    client.delete(ids[1])
    assert client.list()["total"] == 4
    assert not (live_service.settings.artifact_dir / "jobs" / ids[1]).exists()


def test_tokens_are_stored_hashed_and_managed_by_admins(live_service: LiveService) -> None:
    admin = live_service.client()
    created = admin.create_token("harry", ["read"], "ci")
    assert created["token"].startswith("hgr_") and created["scopes"] == ["read"]
    raw_values = [
        value
        for key in live_service.redis.scan_iter("hgrender:token:*")
        for value in live_service.redis.hgetall(key).values()
    ]
    assert created["token"].encode() not in raw_values  # only the SHA-256 is kept
    harry = live_service.client(created["token"])
    assert harry.list()["total"] == 0
    with pytest.raises(Exception) as error:
        harry.create_token("x", ["admin"])
    assert getattr(error.value, "status_code", None) == 403
    assert admin.http.delete(f"/v1/tokens/{created['id']}").status_code == 204
    assert live_service.get("/v1/jobs", token=created["token"]).status_code == 401


def test_rate_limit_answers_429(live_service: LiveService) -> None:
    registry = TokenRegistry(live_service.redis)
    secret, info = registry.create("ivan", ("read",))
    limit = live_service.settings.rate_limit_per_minute
    # Pre-fill this minute's counter to just below the limit; the limit is then hit within two requests.
    window = int(time.time() // 60)
    live_service.redis.set(counter_key(info.id, window), limit - 1, ex=120)
    live_service.redis.set(counter_key(info.id, window + 1), limit - 1, ex=180)
    statuses = [live_service.get("/v1/jobs", token=secret).status_code for _ in range(2)]
    assert statuses == [200, 429]
    response = live_service.get("/v1/jobs", token=secret)
    assert response.status_code == 429 and int(response.headers["retry-after"]) >= 1


def test_rate_limit_counts_reach_the_shared_counter(live_service: LiveService) -> None:
    """Requests are written to Redis in batches (service.rate_limit): every one arrives there, so other
    API processes see them, and what other processes counted limits this one."""
    secret, info = TokenRegistry(live_service.redis).create("judy", ("read",))
    requests = 7
    windows = {int(time.time() // 60)}
    for _ in range(requests):
        assert live_service.get("/v1/jobs", token=secret).status_code == 200
    windows.add(int(time.time() // 60))  # the requests may straddle a minute boundary

    def shared_count() -> int:
        return sum(int(live_service.redis.get(counter_key(info.id, w)) or 0) for w in windows)

    deadline = time.monotonic() + 5
    while shared_count() < requests and time.monotonic() < deadline:
        time.sleep(0.05)
    assert shared_count() == requests
    # Another process counted the rest of this minute's (and the next's) allowance: this one must refuse.
    limit = live_service.settings.rate_limit_per_minute
    window = int(time.time() // 60)
    for w in (window, window + 1):
        live_service.redis.incrby(counter_key(info.id, w), limit)
    assert live_service.get("/v1/jobs", token=secret).status_code == 429


def test_health_readiness_metrics_schema(live_service: LiveService) -> None:
    assert live_service.get("/healthz", token="").json() == {"status": "ok"}
    ready = live_service.get("/readyz", token="")  # no worker runs in these tests: not ready
    assert ready.status_code == 503
    assert ready.json()["checks"] == {
        "redis": "ok",
        "workers": "error: no queue worker is alive",
        "store": "ok",
    }
    metrics = live_service.get("/metrics", token="").text
    assert 'hgrender_queue_depth{queue="default"}' in metrics
    assert 'hgrender_jobs{status="queued"}' in metrics
    assert "hgrender_api_request_duration_seconds_bucket" in metrics
    schema = live_service.get("/v1/schemas/scene", token=live_service.admin_token).json()
    assert "properties" in schema or "$defs" in schema
    spec = live_service.get("/openapi.json", token="").json()
    assert {"/v1/jobs", "/v1/jobs/{job_id}/events", "/v1/coherence", "/metrics"} <= set(spec["paths"])
    references = set(re.findall(r'"\$ref": "#/components/schemas/([^"]+)"', json.dumps(spec)))
    assert references <= set(spec["components"]["schemas"]), references - set(spec["components"]["schemas"])
    body = spec["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert body["properties"]["scene"]["type"] == "object" and body["examples"]


def test_metrics_jobs_by_state_match_listing(live_service: LiveService) -> None:
    client = live_service.client()
    by_status = {s: client.list(status=s)["total"] for s in ("queued", "canceled")}
    metrics = live_service.get("/metrics", token="").text
    for status, count in by_status.items():
        assert f'hgrender_jobs{{status="{status}"}} {count}' in metrics


def test_coherence_endpoint_matches_van_cittert_zernike(live_service: LiveService) -> None:
    """A uniform disk of radius a seen from r has |μ| curvature of 2J1(v)/v: Σ⊥ = a²/4 per axis, so
    ℓ = 1/sqrt((k/r)² a²/4) = 2r/(k a) (the calculator's own closed form; relative tolerance 1e-9)."""
    client = live_service.client()
    result = client.coherence(source="disk", radius_m=0.01, distance_m=2.0, wavelength_nm=550.0)
    k = 2 * math.pi / 550e-9
    expected_um = 2 * 2.0 / (k * 0.01) * 1e6
    assert result["l1_um"] == pytest.approx(expected_um, rel=1e-9)
    response = client.http.post("/v1/coherence", json={"source": "disk", "radius_m": -1, "distance_m": 1})
    assert response.status_code == 422 and response.json()["detail"].startswith("radius_m")


def test_openapi_example_scene_is_valid() -> None:
    from schemas import validate_scene
    from service.models import EXAMPLE_SCENE, JobCreate

    validate_scene(EXAMPLE_SCENE)
    example = JobCreate.model_json_schema()["examples"][0]
    assert JobCreate.model_validate(example).scene == EXAMPLE_SCENE


def test_auth_off_makes_every_caller_the_local_developer(live_service: LiveService) -> None:
    from fastapi.testclient import TestClient

    from service.main import create_app

    settings = live_service.settings.model_copy(update={"auth": "off"})
    with TestClient(create_app(settings)) as client:
        response = client.post("/v1/jobs", json={"scene": tiny_scene(), "chunks": 1})
        assert response.status_code == 202
        job = client.get(f"/v1/jobs/{response.json()['id']}").json()
        assert job["owner"] == "local"
        assert client.get("/v1/tokens").status_code == 200  # every scope, admin included
