"""Liveness (``/healthz``), readiness (``/readyz``: Redis and artifact store reachable) and ``/metrics``."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse

from service.api.deps import JobsDep, RedisDep, StoreDep
from service.metrics import render_metrics

router = APIRouter(tags=["health"])


@router.get("/healthz", summary="Liveness")
def healthz() -> dict[str, str]:
    return {"status": "ok"}


@router.get(
    "/readyz",
    summary="Readiness: Redis and the artifact store answer",
    responses={503: {"description": "A dependency is unreachable; `checks` says which."}},
)
def readyz(client: RedisDep, store: StoreDep) -> JSONResponse:
    checks: dict[str, str] = {}
    try:
        client.ping()
        checks["redis"] = "ok"
    except Exception as error:  # any failure means "not ready"; the message says why
        checks["redis"] = f"error: {error}"
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
def metrics(request: Request, client: RedisDep, jobs: JobsDep) -> PlainTextResponse:
    text = render_metrics(client, jobs, request.app.state.latency)
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")
