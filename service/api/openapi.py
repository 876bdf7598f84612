"""The OpenAPI document (``/openapi.json``) and its pages (``/docs`` Swagger UI, ``/redoc`` ReDoc).

The pages load their JavaScript and CSS from this server (``fastapi-offline`` ships Swagger UI and ReDoc
in its wheel), so they work without internet access. ``document_common_responses`` adds to every
operation the error answers that come from outside its route function, each with the ``Problem`` body
the exception handlers (``service.api.errors``) actually send:

* 401/403/429/503 on operations behind a bearer token (auth dependency, rate limit, Redis down);
* 400 (a body that cannot be parsed, e.g. broken multipart) and 413 (``BodySizeLimitMiddleware``) on
  operations with a request body;
* 422 as ``Problem`` instead of FastAPI's ``HTTPValidationError``, whose ``detail`` is a list: the
  handler sends ``detail`` as one string plus ``errors``.
"""

from __future__ import annotations

from http import HTTPStatus
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from pydantic import BaseModel

from service.models import Problem

# Operation-level answers that do not depend on the route (status → description).
AUTH_RESPONSES: dict[str, str] = {
    "401": "Missing, malformed or unknown bearer token.",
    "403": "The token lacks the scope this operation needs.",
    "429": "Rate limit of the token exceeded; `Retry-After` says when to retry (s).",
    "503": "Redis unavailable; `Retry-After` says when to retry (s).",
}
BODY_RESPONSES: dict[str, str] = {
    "400": "Body that cannot be parsed (e.g. malformed multipart).",
    "413": "Body larger than `HGRENDER_MAX_REQUEST_BYTES`.",
}
VALIDATION_DESCRIPTION = "Invalid request: `detail` names the first field, `errors` lists every problem."
PROBLEM_REF = {"$ref": "#/components/schemas/Problem"}
RETRY_AFTER_HEADER = {
    "Retry-After": {"description": "Seconds to wait before retrying.", "schema": {"type": "integer"}}
}


def problems(**descriptions: str) -> dict[int | str, dict[str, Any]]:
    """Route-level error answers with the ``Problem`` body: ``problems(not_found="No such job.")`` →
    {404: ...}; the names are ``HTTPStatus`` members in lower case (``conflict``, ``not_found``, ...)."""
    return {
        HTTPStatus[name.upper()].value: {"model": Problem, "description": description}
        for name, description in descriptions.items()
    }


AUTH_ERRORS = problems(unauthorized="Missing or invalid token.", forbidden="Token lacks the scope.")
"""What every route behind a bearer token may answer (``document_common_responses`` completes them)."""
JOB_ERRORS = AUTH_ERRORS | problems(
    not_found="No such job (or another owner's).", too_many_requests="Rate limit exceeded."
)
"""What every route of one job (``/v1/jobs/{job_id}...``) may answer."""


def request_body(content: dict[str, Any]) -> dict[str, Any]:
    """``openapi_extra`` of a route that reads its body itself (FastAPI then documents none): a required
    body of the media types in ``content`` (media type → schema, example)."""
    return {"requestBody": {"required": True, "content": content}}


def form_fields_schema(model: type[BaseModel], **files: dict[str, Any]) -> dict[str, Any]:
    """The multipart form of ``model``'s fields (text in the form, validated as ``model``: its JSON
    schema without the ``null`` of optional fields) plus the file fields ``files`` (name → schema), which
    are required."""
    properties: dict[str, Any] = {}
    for name, schema in model.model_json_schema()["properties"].items():
        (value,) = [variant for variant in schema.get("anyOf", [schema]) if variant.get("type") != "null"]
        kept = {key: schema[key] for key in ("description",) if key in schema}
        properties[name] = {key: v for key, v in value.items() if key not in ("title", "default")} | kept
    return {"type": "object", "required": list(files), "properties": files | properties}


def _problem_response(description: str, status: str) -> dict[str, Any]:
    response: dict[str, Any] = {
        "description": description,
        "content": {"application/json": {"schema": PROBLEM_REF}},
    }
    if status in ("429", "503"):
        response["headers"] = RETRY_AFTER_HEADER
    return response


def document_common_responses(document: dict[str, Any]) -> dict[str, Any]:
    """``document`` with the answers listed in the module docstring added to each operation."""
    schemas = document.setdefault("components", {}).setdefault("schemas", {})
    schemas.setdefault("Problem", Problem.model_json_schema(ref_template="#/components/schemas/{model}"))
    for operations in document.get("paths", {}).values():
        for operation in operations.values():
            responses = operation.setdefault("responses", {})
            if "422" in responses or operation.get("parameters") or "requestBody" in operation:
                description = responses.get("422", {}).get("description", "")
                if description in ("", "Validation Error"):
                    description = VALIDATION_DESCRIPTION
                responses["422"] = _problem_response(description, "422")
            added = dict(AUTH_RESPONSES) if operation.get("security") else {}
            if "requestBody" in operation:
                added |= BODY_RESPONSES
            for status, description in added.items():
                if status in responses:
                    # Keep the route's own wording; make the body and headers what the handler sends.
                    description = responses[status].get("description") or description
                responses[status] = _problem_response(description, status)
    # FastAPI's own validation-error schemas are no longer referenced by any operation.
    for unused in ("HTTPValidationError", "ValidationError"):
        schemas.pop(unused, None)
    return document


def install_openapi(app: FastAPI) -> None:
    """Serve ``document_common_responses`` of the generated document at ``app.openapi_url`` (built once)."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            document = get_openapi(
                title=app.title,
                version=app.version,
                description=app.description,
                routes=app.routes,
                tags=app.openapi_tags,
            )
            app.openapi_schema = document_common_responses(document)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]  # FastAPI's documented override point
