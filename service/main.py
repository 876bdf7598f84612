"""The FastAPI application: ``create_app(settings)`` wires settings, Redis, the artifact store, the job
service, middleware, exception handlers and the routers. Never imports Mitsuba or Dr.Jit.

Run it with ``hgrender serve`` (which also starts workers and, without ``REDIS_URL``, a private Redis) or
any ASGI server: ``uvicorn --factory service.main:app_from_env``.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline

from hgcore import __version__
from hgcore.errors import InputError
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.redis_clients import async_redis_client, redis_client
from hgcore.settings import Settings
from hgcore.store import store_from_settings
from service.api.errors import install_exception_handlers
from service.api.middleware import BodySizeLimitMiddleware, LatencyMiddleware
from service.api.openapi import install_openapi
from service.api.routes import coherence, health, jobs, schemas, tokens, viewer, web
from service.api.routes import schedules as regression_routes
from service.auth import RequestAuthenticator, TokenRegistry
from service.jobs import JobService
from service.metrics import LatencyHistogram
from service.viewer_images import ViewerImages

DESCRIPTION = """Render partially-coherent light in Hermite-Gauss space (Steinberg & Yan 2021).

Submit a scene (`POST /v1/jobs`), follow it (`GET /v1/jobs/{id}` or the SSE stream `/events`), and
download its spectral EXR, coherence diagnostics, preview and summary (`/artifacts`). Authenticate with
`Authorization: Bearer <token>`; `hgrender serve` writes a first admin token to `<data dir>/admin.token`.
Errors are `{"detail": "<field>: <what is wrong>"}`, plus `errors` listing every problem of a rejected
request. Interactive pages: `/docs` (Swagger UI) and `/redoc`, served from this server (no CDN).
"""


def create_app(settings: Settings) -> FastAPI:
    """The API for ``settings``; ``settings.redis_url`` must name a running Redis."""
    if not settings.redis_url:
        raise InputError("redis_url: REDIS_URL must be set (hgrender serve starts a private Redis)")
    latency = LatencyHistogram()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        yield
        await app.state.authenticator.aclose()  # writes the request counts still pending
        await app.state.aredis.aclose()
        app.state.redis.close()

    # FastAPIOffline: a plain FastAPI whose /docs and /redoc load Swagger UI and ReDoc from this server.
    app = FastAPIOffline(
        title="hgrender",
        version=__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
        openapi_tags=[
            {"name": "jobs", "description": "Render jobs and their artifacts."},
            {"name": "coherence", "description": "Coherence calculator."},
            {"name": "schemas", "description": "Scene schema."},
            {"name": "tokens", "description": "API tokens (admin)."},
            {"name": "health", "description": "Liveness, readiness, metrics."},
            {"name": "regression", "description": "Regression schedules, runs and baselines."},
        ],
        swagger_ui_parameters={"validatorUrl": None},  # no badge fetched from validator.swagger.io
    )
    install_openapi(app)
    client = redis_client(settings.redis_url, health_check_interval=30)
    store = store_from_settings(settings)
    app.state.settings = settings
    app.state.redis = client
    app.state.aredis = async_redis_client(settings.redis_url)
    app.state.store = store
    app.state.jobs = JobService(JobLifecycle(client, store, aclient=app.state.aredis), settings)
    app.state.tokens = TokenRegistry(client)
    app.state.authenticator = RequestAuthenticator(app.state.aredis, settings.rate_limit_per_minute)
    app.state.scene_limits = settings  # Settings extends SceneLimits: one read of the environment
    app.state.latency = latency

    install_exception_handlers(app)
    for router in (jobs.router, coherence.router, schemas.router, tokens.router, health.router):
        app.include_router(router)
    app.include_router(regression_routes.router)
    app.state.viewer_images = ViewerImages(app.state.jobs, store)  # decoded images, uploaded EXRs
    app.include_router(viewer.router)
    web.install(app)  # the browser viewer at /
    # The last added is outermost: latency also times the 413s the size limit answers before routing.
    app.add_middleware(BodySizeLimitMiddleware, max_bytes=settings.max_request_bytes)
    app.add_middleware(LatencyMiddleware, histogram=latency)
    return app


def app_from_env() -> FastAPI:
    """``create_app(Settings())``, for ASGI servers' ``--factory`` option."""
    return create_app(Settings())
