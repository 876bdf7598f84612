"""Failure webhooks reach a real local HTTP receiver, retried with backoff after it first fails."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import pytest

from hgcore.regression.webhooks import deliver_webhook
from tests.support.webhooks import running_receiver


@pytest.fixture()
def receiver_factory() -> Iterator[Any]:
    with contextlib.ExitStack() as stack:
        yield lambda failures: stack.enter_context(running_receiver(failures))


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
