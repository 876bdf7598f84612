"""A small Python client of the hgrender HTTP API (httpx), used by the CLI and the tests.

>>> client = HgrenderClient("http://127.0.0.1:8000", token=Path("data/admin.token").read_text().strip())
>>> job = client.submit(Path("schemas/examples/cornell_box.json"), spp=16)
>>> final = client.wait(job["id"])               # follows the job's Server-Sent Events
>>> client.download_all(job["id"], Path("out"))  # image.exr, preview.png, summary.json, ...
"""

from __future__ import annotations

import contextlib
import json
import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx

FINAL_STATUSES = frozenset({"succeeded", "failed", "canceled"})


class ApiError(Exception):
    """A non-2xx answer; ``status_code`` and the server's ``detail``."""

    def __init__(self, status_code: int, detail: str, body: Any = None, request: str = "") -> None:
        super().__init__(f"HTTP {status_code}: {detail}")
        self.status_code = status_code
        self.detail = detail
        self.body = body
        self.request = request  # "GET /v1/jobs/…", for messages about a wrong URL

    @property
    def is_success(self) -> bool:
        return 200 <= self.status_code < 300

    @property
    def from_hgrender(self) -> bool:
        """Whether an hgrender API gave this answer: its errors are JSON ``{"detail": ...}`` naming a
        field, while an unknown path or another server gives HTML, or the framework's bare 404/405."""
        return (
            isinstance(self.body, dict)
            and isinstance(self.body.get("detail"), str)
            and self.detail not in ("Not Found", "Method Not Allowed")
        )


class ServiceUnreachableError(Exception):
    """No HTTP answer from ``url``: nothing listens there, the host is unknown, or it timed out."""

    def __init__(self, url: str, reason: str) -> None:
        super().__init__(f"cannot reach {url} ({reason})")
        self.url = url
        self.reason = reason


def _transport_reason(error: httpx.TransportError) -> str:
    """A short lower-case reason: "connection refused", "name or service not known", "timed out"."""
    if isinstance(error, httpx.TimeoutException):
        return "timed out"
    text = str(error) or type(error).__name__
    return re.sub(r"^\[Errno -?\d+\] ", "", text).rstrip(".").lower()


class HgrenderClient:
    """Thin wrapper of the ``/v1`` endpoints; every method returns the decoded JSON. Transport failures
    raise ``ServiceUnreachableError``, non-2xx answers ``ApiError``."""

    def __init__(self, base_url: str, token: str | None = None, timeout_s: float = 60.0) -> None:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.base_url = base_url.rstrip("/")
        self.http = httpx.Client(base_url=self.base_url, headers=headers, timeout=timeout_s)

    @contextlib.contextmanager
    def _reaching(self) -> Iterator[None]:
        try:
            yield
        except httpx.TransportError as error:
            raise ServiceUnreachableError(self.base_url, _transport_reason(error)) from error

    def close(self) -> None:
        self.http.close()

    def __enter__(self) -> HgrenderClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _check(self, response: httpx.Response) -> httpx.Response:
        if response.is_success:
            return response
        try:
            body = response.json()
            detail = body.get("detail", response.text) if isinstance(body, dict) else response.text
        except ValueError:
            body, detail = None, response.text
        request = f"{response.request.method} {response.request.url.path}"
        raise ApiError(response.status_code, str(detail), body, request)

    def _request(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        with self._reaching():
            return self._check(self.http.request(method, path, **kwargs))

    def _json(self, method: str, path: str, **kwargs: Any) -> Any:
        response = self._request(method, path, **kwargs)
        try:
            return response.json()
        except ValueError:  # a 2xx that is not JSON: some other server answered
            request = f"{response.request.method} {response.request.url.path}"
            raise ApiError(response.status_code, "the answer is not JSON", None, request) from None

    # ---- jobs -----------------------------------------------------------------------------------------

    def submit(self, scene: dict[str, Any] | Path, **options: Any) -> dict[str, Any]:
        """Submit a scene dict or file (.json, or a USD file/bundle sent as multipart); ``options`` are
        ``priority``, ``spp``, ``chunks``, ``seed``, ``idempotency_key``, ``name``, ``integrator``,
        ``target_rel_error``, ``time_budget_s``, ``target_quantile`` (the API's job options)."""
        options = {k: v for k, v in options.items() if v is not None}
        if isinstance(scene, dict):
            return self._json("POST", "/v1/jobs", json={"scene": scene, **options})
        path = Path(scene)
        if path.suffix.lower() == ".json":
            return self._json("POST", "/v1/jobs", json={"scene": json.loads(path.read_text()), **options})
        with path.open("rb") as handle:
            files = {"scene": (path.name, handle, "application/octet-stream")}
            data = {k: str(v) for k, v in options.items()}
            return self._json("POST", "/v1/jobs", files=files, data=data)

    def get(self, job_id: str) -> dict[str, Any]:
        return self._json("GET", f"/v1/jobs/{job_id}")

    def list(self, status: str | None = None, offset: int = 0, limit: int = 50) -> dict[str, Any]:
        params: dict[str, Any] = {"offset": offset, "limit": limit}
        if status:
            params["status"] = status
        return self._json("GET", "/v1/jobs", params=params)

    def cancel(self, job_id: str) -> dict[str, Any]:
        return self._json("POST", f"/v1/jobs/{job_id}/cancel")

    def delete(self, job_id: str) -> None:
        self._request("DELETE", f"/v1/jobs/{job_id}")

    def artifacts(self, job_id: str) -> list[dict[str, Any]]:
        return self._json("GET", f"/v1/jobs/{job_id}/artifacts")["items"]

    def download(self, job_id: str, name: str, destination: Path) -> Path:
        """Stream one artifact to ``destination`` (written to a temp name, then renamed)."""
        destination = Path(destination)
        destination.parent.mkdir(parents=True, exist_ok=True)
        tmp_path = destination.with_name(f".{destination.name}.part")
        with self._reaching(), self.http.stream("GET", f"/v1/jobs/{job_id}/artifacts/{name}") as response:
            if not response.is_success:
                response.read()
                self._check(response)
            with tmp_path.open("wb") as out:
                for piece in response.iter_bytes():
                    out.write(piece)
        tmp_path.replace(destination)
        return destination

    def download_all(self, job_id: str, out_dir: Path, include_chunks: bool = False) -> list[Path]:
        """Every artifact (chunk partials and inputs only if asked) into ``out_dir``."""
        return [
            self.download(job_id, item["name"], Path(out_dir) / item["name"])
            for item in self.artifacts(job_id)
            if include_chunks or not item["name"].startswith(("chunks/", "input/"))
        ]

    def events(self, job_id: str, deadline: float | None = None) -> Iterator[tuple[str, dict[str, Any]]]:
        """(event, data) pairs of the job's SSE stream until it ends; TimeoutError once ``deadline``
        (``time.monotonic()``) has passed (checked at every line, the server pings every few seconds)."""
        timeout = httpx.Timeout(self.http.timeout.connect, read=60.0)
        with (
            self._reaching(),
            self.http.stream("GET", f"/v1/jobs/{job_id}/events", timeout=timeout) as response,
        ):
            if not response.is_success:
                response.read()
                self._check(response)
            event, data_lines = "message", []
            for line in response.iter_lines():
                if deadline is not None and time.monotonic() > deadline:
                    raise TimeoutError(f"job_id: {job_id} not finished in time")
                if line.startswith("event:"):
                    event = line[6:].strip()
                elif line.startswith("data:"):
                    data_lines.append(line[5:].strip())
                elif line == "" and data_lines:
                    yield event, json.loads("\n".join(data_lines))
                    event, data_lines = "message", []

    def wait(
        self,
        job_id: str,
        on_event: Callable[[str, dict[str, Any]], None] | None = None,
        timeout_s: float | None = None,
        poll_interval_s: float = 0.5,
    ) -> dict[str, Any]:
        """Follow the job until a final status and return its view: SSE first, polling if the stream
        breaks."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        try:
            for event, data in self.events(job_id, deadline):
                if on_event is not None:
                    on_event(event, data)
                if event == "status" and data.get("status") in FINAL_STATUSES:
                    return data
        except ServiceUnreachableError:
            pass  # a broken stream: fall back to polling below (which reports a service that is down)
        while True:
            view = self.get(job_id)
            if on_event is not None:
                on_event("status", view)
            if view["status"] in FINAL_STATUSES:
                return view
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"job_id: {job_id} not finished after {timeout_s} s")
            time.sleep(poll_interval_s)

    def layers(self, job_id: str) -> dict[str, Any]:
        """The viewer's catalogue of the job's image: ``width``, ``height``, ``partial``, ``layers``."""
        return self._json("GET", f"/v1/jobs/{job_id}/layers")

    def layer(self, job_id: str, name: str) -> bytes:
        """One layer as little-endian float32, row-major, channels interleaved (``rgb``: 3)."""
        return self._request("GET", f"/v1/jobs/{job_id}/layers/{name}", params={"format": "f32"}).content

    # ---- other resources ------------------------------------------------------------------------------

    def create_token(self, owner: str, scopes: list[str], name: str = "") -> dict[str, Any]:
        return self._json("POST", "/v1/tokens", json={"owner": owner, "scopes": scopes, "name": name})

    def coherence(self, **params: Any) -> dict[str, Any]:
        return self._json("POST", "/v1/coherence", json=params)

    def health(self) -> dict[str, Any]:
        return self._json("GET", "/readyz")
