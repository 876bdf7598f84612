"""Prometheus metrics in the text exposition format (version 0.0.4), written by hand.

Exposed: queue depth and running chunks per RQ queue, jobs by status, total render seconds and samples
(counters, from Redis, summed over all workers), mean samples per second, and API request latency as a
histogram per route template, method and status class (kept in this API process).
"""

from __future__ import annotations

import threading
from collections import defaultdict
from collections.abc import Sequence

import redis
from rq import Queue

from hgcore.settings import QUEUE_NAMES
from service.jobs import JobService

LATENCY_BUCKETS_S: tuple[float, ...] = (
    0.001,
    0.0025,
    0.005,
    0.01,
    0.025,
    0.05,
    0.1,
    0.25,
    0.5,
    1.0,
    2.5,
    10.0,
)


class LatencyHistogram:
    """Cumulative request-latency histogram per (route, method, status class); thread-safe."""

    def __init__(self, buckets_s: Sequence[float] = LATENCY_BUCKETS_S) -> None:
        self.buckets_s = tuple(buckets_s)
        self._lock = threading.Lock()
        self._counts: dict[tuple[str, str, str], list[int]] = defaultdict(lambda: [0] * len(self.buckets_s))
        self._sums: dict[tuple[str, str, str], float] = defaultdict(float)
        self._totals: dict[tuple[str, str, str], int] = defaultdict(int)

    def observe(self, route: str, method: str, status_code: int, seconds: float) -> None:
        key = (route, method, f"{status_code // 100}xx")
        with self._lock:
            counts = self._counts[key]
            for i, bound in enumerate(self.buckets_s):
                if seconds <= bound:
                    counts[i] += 1
            self._sums[key] += seconds
            self._totals[key] += 1

    def render(self, name: str) -> list[str]:
        lines = [f"# HELP {name} API request latency (s).", f"# TYPE {name} histogram"]
        with self._lock:
            for (route, method, status), counts in sorted(self._counts.items()):
                labels = f'route="{_escape(route)}",method="{method}",status="{status}"'
                for bound, count in zip(self.buckets_s, counts, strict=True):
                    lines.append(f'{name}_bucket{{{labels},le="{bound}"}} {count}')
                total = self._totals[(route, method, status)]
                lines.append(f'{name}_bucket{{{labels},le="+Inf"}} {total}')
                lines.append(f"{name}_sum{{{labels}}} {self._sums[(route, method, status)]!r}")
                lines.append(f"{name}_count{{{labels}}} {total}")
        return lines


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def render_metrics(client: redis.Redis, jobs: JobService, latency: LatencyHistogram) -> str:
    """The full ``/metrics`` document."""
    lines = [
        "# HELP hgrender_queue_depth RQ jobs (chunks and merges) waiting in each queue.",
        "# TYPE hgrender_queue_depth gauge",
    ]
    queues = [Queue(name, connection=client) for name in QUEUE_NAMES]
    lines += [f'hgrender_queue_depth{{queue="{q.name}"}} {q.count}' for q in queues]
    lines += [
        "# HELP hgrender_queue_running RQ jobs being executed by workers, per queue.",
        "# TYPE hgrender_queue_running gauge",
    ]
    lines += [f'hgrender_queue_running{{queue="{q.name}"}} {q.started_job_registry.count}' for q in queues]
    lines += ["# HELP hgrender_jobs Render jobs by status.", "# TYPE hgrender_jobs gauge"]
    lines += [f'hgrender_jobs{{status="{s}"}} {n}' for s, n in jobs.lifecycle.counts_by_state().items()]
    render_s, samples = jobs.lifecycle.render_totals()
    lines += [
        "# HELP hgrender_render_seconds_total Wall-clock seconds spent rendering chunks.",
        "# TYPE hgrender_render_seconds_total counter",
        f"hgrender_render_seconds_total {render_s!r}",
        "# HELP hgrender_render_samples_total Samples (pixels x spp) rendered.",
        "# TYPE hgrender_render_samples_total counter",
        f"hgrender_render_samples_total {samples}",
        "# HELP hgrender_render_samples_per_second Mean rendering throughput over all chunks.",
        "# TYPE hgrender_render_samples_per_second gauge",
        f"hgrender_render_samples_per_second {samples / render_s if render_s > 0 else 0.0!r}",
    ]
    lines += latency.render("hgrender_api_request_duration_seconds")
    return "\n".join(lines) + "\n"
