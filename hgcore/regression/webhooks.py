"""Failure webhooks: POST a run's JSON report to the schedule's URL, retried with backoff.

A delivery succeeds on any 2xx answer. Connection errors, timeouts and non-2xx answers are retried after
``webhook_retry_intervals_s[i]`` seconds (one attempt more than there are intervals); the outcome (attempts,
last status or error) is stored in the run record so the history shows whether the alert went out.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import httpx


def deliver_webhook(
    url: str,
    payload: dict[str, Any],
    *,
    retry_intervals_s: Sequence[float],
    timeout_s: float,
    sleep: Callable[[float], None] = time.sleep,
) -> dict[str, Any]:
    """POST ``payload`` to ``url`` until a 2xx answer or the retries are spent; returns the outcome."""
    attempts = 0
    last: str = ""
    for delay_s in [0.0, *retry_intervals_s]:
        if delay_s > 0:
            sleep(delay_s)
        attempts += 1
        try:
            response = httpx.post(url, json=payload, timeout=timeout_s)
        except httpx.HTTPError as error:
            last = f"{type(error).__name__}: {error}"
            continue
        last = f"HTTP {response.status_code}"
        if response.is_success:
            return {"url": url, "delivered": True, "attempts": attempts, "last": last}
    return {"url": url, "delivered": False, "attempts": attempts, "last": last}
