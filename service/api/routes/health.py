"""Liveness (``/healthz``), readiness (``/readyz``) and ``/metrics``.

``/healthz`` answers 200 while the API process serves requests at all (restart it when it does not);
``/readyz`` answers 200 only when a submitted job can make progress: Redis and the artifact store answer
and at least one queue worker is alive (send no traffic otherwise; it is not a reason to restart).
"""

from __future__ import annotations

from datetime import UTC, datetime

import redis
from fastapi import APIRouter
from fastapi.responses import JSONResponse, PlainTextResponse
from rq.utils import utcparse
from rq.worker_registration import REDIS_WORKER_KEYS

from hgcore.settings import Settings
from service.api.deps import JobsDep, LatencyDep, RedisDep, SettingsDep, StoreDep
from service.metrics import render_metrics

router = APIRouter(tags=["health"])


@router.get("/healthz", summary="Liveness")
def healthz() -> dict[str, str]:
    return {"status": "ok"}


def live_worker_count(client: redis.Redis, settings: Settings) -> int:
    """Queue workers whose last heartbeat is recent: an idle worker beats every maintenance interval, a
    busy one every monitoring interval; one silent for longer than that plus the heartbeat grace is dead
    (RQ keeps a killed worker's registration for its whole TTL)."""
    worker_keys = client.smembers(REDIS_WORKER_KEYS)
    with client.pipeline(transaction=False) as pipe:
        for key in worker_keys:
            pipe.hget(key, "last_heartbeat")
        beats = pipe.execute()
    period_s = max(settings.worker_maintenance_interval_s, settings.worker_monitoring_interval_s)
    oldest = utcnow_s() - period_s - settings.worker_heartbeat_grace_s
    return sum(1 for beat in beats if beat is not None and utcparse(beat.decode()).timestamp() >= oldest)


def utcnow_s() -> float:
    return datetime.now(UTC).timestamp()


@router.get(
    "/readyz",
    summary="Readiness: Redis and the artifact store answer, and a queue worker is alive",
    responses={
        503: {"description": "A dependency is unreachable or no worker is alive; `checks` says which."}
    },
)
def readyz(client: RedisDep, store: StoreDep, settings: SettingsDep) -> JSONResponse:
    checks: dict[str, str] = {}
    try:
        client.ping()
        checks["redis"] = "ok"
    except Exception as error:  # any failure means "not ready"; the message says why
        checks["redis"] = f"error: {error}"
    try:
        workers = live_worker_count(client, settings) if checks["redis"] == "ok" else 0
        checks["workers"] = "ok" if workers else "error: no queue worker is alive"
    except Exception as error:
        checks["workers"] = f"error: {error}"
    try:
        store.ping()
        checks["store"] = "ok"
    except Exception as error:
        checks["store"] = f"error: {error}"
    ready = all(v == "ok" for v in checks.values())
    return JSONResponse({"status": "ok" if ready else "unavailable", "checks": checks}, 200 if ready else 503)


@router.get(
    "/metrics",
    summary="Prometheus metrics",
    response_class=PlainTextResponse,
    responses={200: {"content": {"text/plain": {}}}},
)
def metrics(client: RedisDep, jobs: JobsDep, latency: LatencyDep) -> PlainTextResponse:
    text = render_metrics(client, jobs, latency)
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")
