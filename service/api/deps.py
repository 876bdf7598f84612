"""Injected dependencies of the routes: settings, Redis, artifact store, job service, caller identity.

Everything comes from ``app.state`` (set up once by ``service.main.create_app``); there are no module
globals. ``require(scope)`` authenticates the bearer token, applies the per-token rate limit and checks
the scope; with ``HGRENDER_AUTH=off`` every caller is the local developer with every scope.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

import redis
import redis.asyncio as aioredis
from fastapi import Depends, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from hgcore.jobs.lifecycle import JobNotFoundError
from hgcore.jobs.views import JobView
from hgcore.settings import Settings
from hgcore.store.base import ArtifactStore
from service.auth import LOCAL_DEVELOPER, AuthenticationError, Principal, RequestAuthenticator, TokenRegistry
from service.jobs import JobService
from service.metrics import LatencyHistogram
from service.viewer_images import ViewerImages

JobId = Annotated[str, Path(pattern=r"^[0-9a-f]{32}$", description="Job id (32 hex digits).")]
"""The ``{job_id}`` path parameter of every route of one job."""

_bearer = HTTPBearer(
    auto_error=False, description="API token (`hgrender token create`; `<data dir>/admin.token`)."
)


# Plain async functions: FastAPI would run sync ones in its thread pool, a hop per dependency.
async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_redis(request: Request) -> redis.Redis:
    return request.app.state.redis


async def get_store(request: Request) -> ArtifactStore:
    return request.app.state.store


async def get_async_redis(request: Request) -> aioredis.Redis:
    return request.app.state.aredis


async def get_jobs(request: Request) -> JobService:
    return request.app.state.jobs


async def get_viewer_images(request: Request) -> ViewerImages:
    return request.app.state.viewer_images


async def get_latency(request: Request) -> LatencyHistogram:
    return request.app.state.latency


async def get_tokens(request: Request) -> TokenRegistry:
    return request.app.state.tokens


SettingsDep = Annotated[Settings, Depends(get_settings)]
RedisDep = Annotated[redis.Redis, Depends(get_redis)]
StoreDep = Annotated[ArtifactStore, Depends(get_store)]
AsyncRedisDep = Annotated[aioredis.Redis, Depends(get_async_redis)]
JobsDep = Annotated[JobService, Depends(get_jobs)]
TokensDep = Annotated[TokenRegistry, Depends(get_tokens)]
LatencyDep = Annotated[LatencyHistogram, Depends(get_latency)]
ViewerImagesDep = Annotated[ViewerImages, Depends(get_viewer_images)]


async def current_principal(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> Principal:
    """The caller, authenticated and counted against its rate limit (one Redis round trip)."""
    if not request.app.state.settings.auth_enabled:
        return LOCAL_DEVELOPER
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise AuthenticationError("authorization: missing bearer token")
    authenticator: RequestAuthenticator = request.app.state.authenticator
    return await authenticator(credentials.credentials)


def require(scope: str) -> Callable[..., Principal]:
    """A dependency that returns the caller if its token has ``scope`` (403 otherwise)."""

    async def dependency(principal: Annotated[Principal, Depends(current_principal)]) -> Principal:
        principal.require(scope)
        return principal

    dependency.__name__ = f"require_{scope}"
    return dependency


Reader = Annotated[Principal, Depends(require("read"))]
Submitter = Annotated[Principal, Depends(require("submit"))]
Admin = Annotated[Principal, Depends(require("admin"))]


def ensure_visible(view: JobView | None, principal: Principal, job_id: str) -> JobView:
    """The job if it exists and the caller may see it; otherwise JobNotFoundError (404: other owners'
    jobs are indistinguishable from missing ones)."""
    if view is None or not principal.can_see(view.owner):
        raise JobNotFoundError(job_id)
    return view


def visible_job(jobs: JobService, principal: Principal, job_id: str) -> JobView:
    return ensure_visible(jobs.get(job_id), principal, job_id)
