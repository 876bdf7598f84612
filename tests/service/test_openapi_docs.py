"""``/docs`` (Swagger UI) and ``/redoc`` render every operation in headless Chromium with every request
that leaves the loopback interface blocked (their assets are served by the API itself), and the OpenAPI
document describes what the API answers: Problem bodies for 400/401/413/422, the EXR media type of
artifacts, the SSE media type, an example for every request body."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

import httpx
import pytest

from tests.support.browser import screenshot
from tests.support.live_service import LiveService

LOOPBACK_HOSTS = {"127.0.0.1", "localhost", "::1"}


def operations(document: dict[str, Any]) -> list[tuple[str, str, dict[str, Any]]]:
    return [
        (path, method, operation)
        for path, methods in document["paths"].items()
        for method, operation in methods.items()
    ]


@contextlib.contextmanager
def offline_page(chromium: Any, url: str, screenshot_name: str) -> Iterator[tuple[Any, list[str]]]:
    """A page at ``url`` whose non-loopback requests are aborted and recorded: (page, the blocked URLs).
    A screenshot is taken when the block ends (``test-artifacts/<screenshot_name>.png``)."""
    context = chromium.new_context(viewport={"width": 1400, "height": 900})
    blocked: list[str] = []

    def route(handle: Any) -> None:
        if urlsplit(handle.request.url).hostname in LOOPBACK_HOSTS:
            handle.continue_()
        else:
            blocked.append(handle.request.url)
            handle.abort()

    context.route("**/*", route)
    try:
        page = context.new_page()
        page.goto(url)
        yield page, blocked
        screenshot(page, screenshot_name)
    finally:
        context.close()


@pytest.mark.browser
def test_swagger_ui_renders_every_operation_offline(live_service: LiveService, chromium: Any) -> None:
    document = httpx.get(live_service.base_url + "/openapi.json", timeout=30).json()
    with offline_page(chromium, live_service.base_url + "/docs", "docs-swagger-offline") as (page, blocked):
        page.wait_for_selector(".opblock", timeout=30_000)
        assert page.locator(".opblock").count() == len(operations(document))
        assert page.locator(".opblock-summary-path", has_text="/v1/jobs/{job_id}/events").count() == 1
        assert page.locator(".info .title").inner_text().startswith("hgrender")
    assert blocked == []  # nothing was even requested from outside


@pytest.mark.browser
def test_redoc_renders_every_operation_offline(live_service: LiveService, chromium: Any) -> None:
    document = httpx.get(live_service.base_url + "/openapi.json", timeout=30).json()
    with offline_page(chromium, live_service.base_url + "/redoc", "docs-redoc-offline") as (page, blocked):
        page.wait_for_selector("[data-section-id*='/operation/']", timeout=30_000)
        sections = page.eval_on_selector_all(
            "[data-section-id*='/operation/']", "nodes => nodes.map(n => n.dataset.sectionId)"
        )
        ids = {section.rsplit("/operation/", 1)[1] for section in sections}
        assert ids == {operation["operationId"] for _, _, operation in operations(document)}
    # ReDoc's bundle hard-codes its "API docs by Redocly" footer logo to its CDN (no option turns it
    # off); that image is all it asks the outside for, and the page works without it.
    assert all(url == "https://cdn.redoc.ly/redoc/logo-mini.svg" for url in blocked), blocked


def test_document_names_error_bodies_media_types_and_examples(live_service: LiveService) -> None:
    document = httpx.get(live_service.base_url + "/openapi.json", timeout=30).json()
    problem = {"$ref": "#/components/schemas/Problem"}
    for path, method, operation in operations(document):
        responses = operation["responses"]
        where = f"{method.upper()} {path}"
        if operation.get("security"):
            for status in ("401", "403", "429", "503"):
                assert responses[status]["content"]["application/json"]["schema"] == problem, (where, status)
        if "requestBody" in operation:
            for status in ("400", "413", "422"):
                assert responses[status]["content"]["application/json"]["schema"] == problem, (where, status)
            for media_type, media in operation["requestBody"]["content"].items():
                schema = media.get("schema", {})
                if "$ref" in schema:
                    schema = document["components"]["schemas"][schema["$ref"].rsplit("/", 1)[-1]]
                assert media.get("example") or schema.get("examples"), (where, media_type)
    assert "HTTPValidationError" not in document["components"]["schemas"]
    download = document["paths"]["/v1/jobs/{job_id}/artifacts/{name}"]["get"]["responses"]["200"]["content"]
    assert {"image/x-exr", "image/png", "application/json", "application/octet-stream"} <= set(download)
    events = document["paths"]["/v1/jobs/{job_id}/events"]["get"]["responses"]["200"]["content"]
    assert list(events) == ["text/event-stream"]
    assert events["text/event-stream"]["schema"]["properties"]["event"]["enum"] == ["status", "progress"]


def test_docs_assets_are_served_locally(live_service: LiveService) -> None:
    html = httpx.get(live_service.base_url + "/docs", timeout=30).text
    assert "cdn.jsdelivr.net" not in html and "unpkg.com" not in html
    script = httpx.get(live_service.base_url + "/static-offline-docs/swagger-ui-bundle.js", timeout=30)
    assert script.status_code == 200 and len(script.content) > 100_000
