"""Failure webhooks reach a real local HTTP receiver, retried with backoff after it first fails."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest

from service.regression.webhooks import deliver_webhook


class Receiver:
    """Answers the first ``failures`` POSTs with 503, later ones with 204; records every body."""

    def __init__(self, failures: int) -> None:
        self.failures = failures
        self.bodies: list[dict[str, Any]] = []
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                receiver.bodies.append(body)
                self.send_response(503 if len(receiver.bodies) <= receiver.failures else 204)
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)


@pytest.fixture()
def receiver_factory() -> Iterator[Any]:
    started: list[Receiver] = []

    def start(failures: int) -> Receiver:
        receiver = Receiver(failures)
        receiver.thread.start()
        started.append(receiver)
        return receiver

    yield start
    for receiver in started:
        receiver.server.shutdown()
        receiver.server.server_close()


def test_delivery_retries_after_the_receiver_first_fails(receiver_factory: Any) -> None:
    receiver = receiver_factory(failures=2)
    sleeps: list[float] = []
    payload = {"event": "regression.failed", "run": {"id": "r1", "reasons": ["cornell_box: rel_rmse ..."]}}
    outcome = deliver_webhook(
        receiver.url, payload, retry_intervals_s=[0.05, 0.1, 0.2], timeout_s=5, sleep=sleeps.append
    )
    assert outcome == {"url": receiver.url, "delivered": True, "attempts": 3, "last": "HTTP 204"}
    assert sleeps == [0.05, 0.1]  # backoff before retries 1 and 2; no third retry needed
    assert receiver.bodies == [payload] * 3


def test_delivery_gives_up_after_the_last_retry(receiver_factory: Any) -> None:
    receiver = receiver_factory(failures=10)
    outcome = deliver_webhook(receiver.url, {"x": 1}, retry_intervals_s=[0.01], timeout_s=5)
    assert outcome["delivered"] is False and outcome["attempts"] == 2 and outcome["last"] == "HTTP 503"


def test_unreachable_receiver_is_reported() -> None:
    outcome = deliver_webhook("http://127.0.0.1:9/none", {"x": 1}, retry_intervals_s=[0.0], timeout_s=1)
    assert outcome["delivered"] is False and outcome["attempts"] == 2 and "Error" in outcome["last"]
