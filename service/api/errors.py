"""Exception → HTTP response mapping. Every error body is ``{"detail": "<field>: <what is wrong>"}``,
plus ``errors`` (a list) for scene and request validation problems."""

from __future__ import annotations

import json
import re
from typing import Any

import redis
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.requests import ClientDisconnect

from hgcore.errors import InputError
from hgcore.jobs.lifecycle import JobNotFoundError
from hgcore.store.base import ArtifactNotFoundError, validate_key
from schemas import SceneError
from service.auth import AuthenticationError, PermissionDeniedError, RateLimitedError
from service.jobs import JobConflictError

CLIENT_CLOSED_REQUEST = 499
"""Status recorded when the client hung up before its request body arrived (nginx's convention): a 4xx,
so a disconnect never counts as a server error in ``/metrics``; nobody receives the response."""

_STORE_PREFIX = re.compile(r"^jobs/[0-9a-f]{32}/")


def _artifact_name(key: str) -> str | None:
    """The user-facing artifact name of a store key or requested name, or None when it is not a safe
    name (a traversal attempt, say): error messages never echo store layout or arbitrary paths."""
    name = _STORE_PREFIX.sub("", key)
    try:
        return validate_key(name)
    except ValueError:
        return None


def problem(status_code: int, detail: str, errors: list[Any] | None = None, **headers: str) -> JSONResponse:
    body: dict[str, Any] = {"detail": detail}
    if errors is not None:
        body["errors"] = errors
    return JSONResponse(body, status_code=status_code, headers=headers or None)


def _validation_problem(errors: list[dict[str, Any]]) -> JSONResponse:
    first = errors[0] if errors else {"loc": [], "msg": "invalid request"}
    location = list(first.get("loc", ()))
    if len(location) > 1 and location[0] in {"body", "query", "path", "header"}:
        location = location[1:]  # name the field itself, not where FastAPI found it
    field = ".".join(str(part) for part in location) or "body"
    return problem(422, f"{field}: {first.get('msg', 'invalid')}", errors)


def install_exception_handlers(app: FastAPI) -> None:
    @app.exception_handler(SceneError)
    async def scene_error(_: Request, error: SceneError) -> JSONResponse:
        first = error.problems[0]
        detail = f"scene: {first['pointer'] or '/'}: {first['message']}"
        return problem(422, detail, [dict(p) for p in error.problems])

    @app.exception_handler(ValidationError)
    async def model_error(_: Request, error: ValidationError) -> JSONResponse:
        return _validation_problem(json.loads(error.json(include_url=False, include_input=False)))

    @app.exception_handler(RequestValidationError)
    async def request_error(_: Request, error: RequestValidationError) -> JSONResponse:
        errors = [{k: v for k, v in e.items() if k in {"loc", "msg", "type"}} for e in error.errors()]
        return _validation_problem(errors)

    # Bad input names its field (hgcore.errors.InputError): 422. Any other exception, a plain ValueError
    # included, is a bug: Starlette answers 500 and the server logs its traceback.
    @app.exception_handler(InputError)
    async def input_error(_: Request, error: InputError) -> JSONResponse:
        return problem(422, str(error))

    @app.exception_handler(AuthenticationError)
    async def unauthenticated(_: Request, error: AuthenticationError) -> JSONResponse:
        return problem(401, str(error), **{"WWW-Authenticate": "Bearer"})

    @app.exception_handler(PermissionDeniedError)
    async def forbidden(_: Request, error: PermissionDeniedError) -> JSONResponse:
        return problem(403, str(error))

    @app.exception_handler(RateLimitedError)
    async def rate_limited(_: Request, error: RateLimitedError) -> JSONResponse:
        return problem(429, f"authorization: {error}", **{"Retry-After": str(error.retry_after_s)})

    @app.exception_handler(JobNotFoundError)
    async def job_not_found(_: Request, error: JobNotFoundError) -> JSONResponse:
        return problem(404, f"job_id: no job {error.args[0]!r}")

    @app.exception_handler(ArtifactNotFoundError)
    async def artifact_not_found(_: Request, error: ArtifactNotFoundError) -> JSONResponse:
        name = _artifact_name(str(error.args[0]) if error.args else "")
        return problem(404, f"name: no artifact {name!r}" if name else "name: no such artifact")

    @app.exception_handler(ClientDisconnect)
    async def client_disconnected(_: Request, error: ClientDisconnect) -> JSONResponse:
        return problem(CLIENT_CLOSED_REQUEST, "body: the client closed the connection mid-request")

    @app.exception_handler(JobConflictError)
    async def conflict(_: Request, error: JobConflictError) -> JSONResponse:
        return problem(409, str(error))

    @app.exception_handler(redis.exceptions.ConnectionError)
    async def redis_down(_: Request, error: redis.exceptions.ConnectionError) -> JSONResponse:
        return problem(503, f"redis: unavailable ({error})", **{"Retry-After": "5"})
