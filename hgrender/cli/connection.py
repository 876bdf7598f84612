"""Where the client commands find the service and their token, and how they report what went wrong.

The URL comes from ``--url``, else ``HGRENDER_URL``, else ``http://127.0.0.1:8000``; the token from
``--token``, else ``HGRENDER_TOKEN``, else ``<--data-dir>/admin.token`` (written by ``hgrender serve``).
``ServiceTarget`` remembers which of these it used, so that a refused connection or a 401 is reported
as one line naming the URL or token source tried and how to set it (exit 2), never as a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hgrender.cli import CliError

DEFAULT_URL = "http://127.0.0.1:8000"
URL_VARIABLE = "HGRENDER_URL"
TOKEN_VARIABLE = "HGRENDER_TOKEN"
TOKEN_FILE_NAME = "admin.token"


def add_client_options(parser: argparse.ArgumentParser, url_default_help: str | None = None) -> None:
    """``--url``, ``--token`` and ``--data-dir`` (defaults resolved later, so their source is known)."""
    parser.add_argument(
        "--url",
        default=None,
        help=url_default_help or f"service base URL (default: ${URL_VARIABLE}, else {DEFAULT_URL})",
    )
    parser.add_argument(
        "--token", default=None, help=f"API token (default: ${TOKEN_VARIABLE}, else <data dir>/admin.token)"
    )
    parser.add_argument(
        "--data-dir",
        type=Path,
        default=Path("./data"),
        help="data dir of the `hgrender serve` whose admin.token to use when no token is given",
    )


def _checked_url(url: str, source: str) -> str:
    import httpx

    try:
        parsed = httpx.URL(url)
    except httpx.InvalidURL as error:
        raise CliError(f"url: {url!r} (from {source}) is not a URL: {error}") from None
    if parsed.scheme not in ("http", "https") or not parsed.host:
        raise CliError(f"url: {url!r} (from {source}) is not an http:// or https:// URL; e.g. {DEFAULT_URL}")
    return url.rstrip("/")


@dataclass(frozen=True)
class ServiceTarget:
    """The service URL and token a command uses, with where each came from (for messages)."""

    url: str
    url_source: str
    token: str | None
    token_source: str

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ServiceTarget:
        if args.url is not None:
            url, url_source = args.url, "--url"
        elif os.environ.get(URL_VARIABLE):
            url, url_source = os.environ[URL_VARIABLE], URL_VARIABLE
        else:
            url, url_source = DEFAULT_URL, "the default"
        token_file = Path(args.data_dir) / TOKEN_FILE_NAME
        if args.token:
            token, token_source = args.token, "--token"
        elif os.environ.get(TOKEN_VARIABLE):
            token, token_source = os.environ[TOKEN_VARIABLE], TOKEN_VARIABLE
        elif token_file.is_file():
            token, token_source = token_file.read_text().strip(), str(token_file)
        else:
            token = None
            token_source = f"nowhere: no --token, {TOKEN_VARIABLE} unset, no {token_file}"
        return cls(_checked_url(url, url_source), url_source, token, token_source)

    def client(self) -> Any:
        from hgrender.client import HgrenderClient

        return HgrenderClient(self.url, token=self.token)

    @contextlib.contextmanager
    def reporting(self, subject: str = "") -> Iterator[None]:
        """Turn the client's errors into ``CliError``s that say what to change."""
        from hgrender.client import ApiError, ServiceUnreachableError

        try:
            yield
        except ServiceUnreachableError as error:
            raise CliError(self.unreachable_message(error.reason)) from None
        except ApiError as error:
            raise CliError(self.api_error_message(error, subject)) from None

    def unreachable_message(self, reason: str) -> str:
        return (
            f"url: cannot reach the hgrender service at {self.url} ({reason}; URL from {self.url_source}); "
            f"start it with `hgrender serve` or set its address with --url or {URL_VARIABLE}"
        )

    def api_error_message(self, error: Any, subject: str = "") -> str:
        """One line, or for a rejected request every problem the API listed, one per line
        (``subject``, e.g. the scene file's name, says what was rejected)."""
        if not error.from_hgrender:
            return (
                f"url: no hgrender API at {self.url} (URL from {self.url_source}): HTTP {error.status_code} "
                f"{'with a non-JSON answer ' if error.is_success else ''}for {error.request}; set the "
                f"service's base URL, e.g. {DEFAULT_URL}, with --url or {URL_VARIABLE}"
            )
        if error.status_code == 401:
            return (
                f"{error.detail} (HTTP 401; token from {self.token_source}); pass a valid token with "
                f"--token or {TOKEN_VARIABLE}, or --data-dir DIR of the `hgrender serve` that wrote "
                f"DIR/{TOKEN_FILE_NAME} (`hgrender token create` makes more)"
            )
        problems = validation_problems(error.body)
        if not problems:
            return str(error)
        count = f"{len(problems)} problem{'s' if len(problems) > 1 else ''}"
        lines = [f"HTTP {error.status_code}: {count}{f' in {subject}' if subject else ''}:"]
        lines += [f"  {location}: {message}" for location, message in problems]
        return "\n".join(lines)


def validation_problems(body: Any) -> list[tuple[str, str]]:
    """(location, message) of every problem an error body lists: scene problems carry a JSON pointer,
    request problems a pydantic ``loc`` (its leading ``body``/``query``/... is dropped)."""
    if not isinstance(body, dict) or not isinstance(body.get("errors"), list):
        return []
    problems = []
    for item in body["errors"]:
        if not isinstance(item, dict):
            continue
        if "pointer" in item:
            problems.append((item["pointer"] or "/", str(item.get("message", ""))))
            continue
        location = list(item.get("loc", ()))
        if len(location) > 1 and location[0] in ("body", "query", "path", "header"):
            location = location[1:]
        problems.append((".".join(str(part) for part in location) or "body", str(item.get("msg", ""))))
    return problems
