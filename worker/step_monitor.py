"""What a running step and its job tell each other, through the job's ``JobLifecycle``: the step's
progress (throttled), whether the job still wants it (a polled cancel), and a noise-target job's previews
of the rounds so far. The renderer calls these back (``progress``, ``should_stop``, ``on_round``)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from hgcore import noise_target
from hgcore.artifacts.pixel_sums import write_partial_rows
from hgcore.artifacts.running_sums import RunningSums
from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.jobs.status import JobStatus
from hgcore.noise_target import ImageErrors, NoiseTarget

CANCEL_POLL_INTERVAL_S = 0.5
"""How often a running chunk re-reads its job's status (a cancel stops it within this plus one pass)."""
PREVIEW_OVERHEAD_RATIO = 10.0
"""A noise-target job publishes a round's preview when it rendered at least this many times the last
publication's cost since then: previews add at most the first one's cost plus 1/10 to the render."""


class ProgressReporter:
    """Forwards a chunk's progress to its job, at most once per ``interval_s``."""

    def __init__(self, lifecycle: JobLifecycle, job_id: str, index: int, interval_s: float) -> None:
        self.lifecycle, self.job_id, self.index, self.interval_s = lifecycle, job_id, index, interval_s
        self._last_s = 0.0

    def __call__(self, fraction: float) -> None:
        now = time.monotonic()
        if now - self._last_s >= self.interval_s:
            self._last_s = now
            self.lifecycle.report_progress(self.job_id, self.index, fraction)


class CancelPoll:
    """``should_stop`` for the renderer: True once the job was canceled or deleted."""

    def __init__(self, lifecycle: JobLifecycle, job_id: str) -> None:
        self.lifecycle, self.job_id = lifecycle, job_id
        self._last_s = 0.0
        self._stop = False

    def __call__(self, force: bool = False) -> bool:
        now = time.monotonic()
        if not self._stop and (force or now - self._last_s >= CANCEL_POLL_INTERVAL_S):
            self._last_s = now
            self._stop = self.lifecycle.status(self.job_id) in {JobStatus.CANCELED, None}
        return self._stop


class RoundPreviews:
    """``on_round`` of a noise-target job: after a round that another follows, publish the image of the
    rounds so far where a multi-chunk job's finished chunks are, as chunk 0's partial (a target job is one
    chunk; atomic, replaced round by round, so the viewer's merge of the chunk partials shows it), with the
    block of the rounds so far (``JobLifecycle.publish_round``; the viewer refreshes when its round count
    changes). The partial is streamed row band by row band (one tile's float32 table at a time) from the
    running sums the render keeps on disk anyway; the final artifacts are written from the same sums.

    Publishing costs time that grows with the image (at 1024² × 32 bands: a 368 MiB partial written and
    stored, and the per-band errors, ≈ 3–5 s on 2 cores), while a round near the target can be short
    (the next round adds at least N/16 spp). So the first round is always published (the viewer has an
    image early) and a later one only once the render time since the last publication is at least
    ``PREVIEW_OVERHEAD_RATIO`` times that publication's cost; small images publish every round."""

    def __init__(
        self, lifecycle: JobLifecycle, job_id: str, target: NoiseTarget, seed: int, work_dir: Path
    ) -> None:
        self.lifecycle, self.job_id, self.target, self.seed = lifecycle, job_id, target, seed
        self.path = work_dir / "round-preview.npz"
        self.published_at_render_s: float | None = None  # render seconds at the last publication
        self.cost_s = 0.0  # what the last publication took (wall seconds)

    def __call__(self, running: RunningSums, errors: ImageErrors, rounds: list[dict[str, Any]]) -> None:
        render_s = rounds[-1]["seconds"]
        if (
            self.published_at_render_s is not None
            and render_s - self.published_at_render_s < PREVIEW_OVERHEAD_RATIO * self.cost_s
        ):
            return
        started = time.perf_counter()
        self._publish(running, errors, rounds)
        self.published_at_render_s, self.cost_s = render_s, time.perf_counter() - started

    def _publish(self, running: RunningSums, errors: ImageErrors, rounds: list[dict[str, Any]]) -> None:
        from worker.render.renderer import tile_bands

        width, height = running.width, running.height
        row_bands = running.row_bands(tile_bands(width, height))
        write_partial_rows(
            self.path,
            width,
            height,
            running.band_count,
            row_bands,
            running.sample_count,
            rounds[-1]["seconds"],
            0,
            self.seed,
        )
        block = noise_target.summary_block(self.target, errors, rounds, None)
        self.lifecycle.publish_round(self.job_id, self.path, block)
