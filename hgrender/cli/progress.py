"""Progress on stderr for long CLI commands (``render``, ``submit --wait``, ``view --tev``).

On a terminal it is a tqdm bar that redraws in place and shows the job's status and chunk counts
(``running, 2/4 chunks, eta 12 s``); without one (CI logs, pipes) it writes one line per step instead
of carriage-return redraws: a line whenever the status or the chunks done change, or the progress
passes another 10 %. Percentages are rounded down, so 100 % means done: a running job whose samples are
all rendered (progress ``MERGE_PENDING_PROGRESS``) says ``merging`` while its merge step runs.
"""

from __future__ import annotations

import math
import sys
from typing import Any, TextIO

from hgcore.jobs.status import MERGE_PENDING_PROGRESS

# Without a terminal, a line is written each time the progress crosses a multiple of this.
LINE_STEP = 0.1


def describe_step(
    status: str | None, chunks_done: int | None, chunks_total: int | None, eta_s: float | None
) -> str:
    """``running, 2/4 chunks, eta 12 s`` (parts that are unknown are left out)."""
    if status == "merging":
        return "merging: all samples rendered, writing the image"
    parts = [status] if status else []
    if chunks_total:
        parts.append(f"{chunks_done or 0}/{chunks_total} chunks")
    if eta_s is not None and status == "running":
        parts.append(f"eta {eta_s:.0f} s")
    return ", ".join(parts)


class ProgressDisplay:
    """``update(fraction, ...)`` as often as you like; ``close()`` at the end (or use ``with``)."""

    def __init__(
        self, label: str, stream: TextIO | None = None, enabled: bool = True, tty: bool | None = None
    ) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = self.stream.isatty() if tty is None else tty
        self._last_line_key: tuple[Any, ...] | None = None
        self._bar: Any = None
        if enabled and self.tty:
            from tqdm import tqdm

            self._bar = tqdm(
                total=100,
                file=self.stream,
                desc=label,
                # `{unit}` carries the step text verbatim (`{postfix}` would prefix it with ", ").
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {unit} [{elapsed}<{remaining}]",
                unit="",
            )

    def update(
        self,
        fraction: float,
        status: str | None = None,
        chunks_done: int | None = None,
        chunks_total: int | None = None,
        eta_s: float | None = None,
    ) -> None:
        if not self.enabled:
            return
        fraction = min(max(float(fraction), 0.0), 1.0)
        if status == "running" and fraction >= MERGE_PENDING_PROGRESS:
            status = "merging"
        step = describe_step(status, chunks_done, chunks_total, eta_s)
        percent = math.floor(100 * fraction)
        if self._bar is not None:
            self._bar.n = percent
            self._bar.unit = step
            self._bar.refresh()
            return
        # One line per step: the ETA alone changing is not a step (it changes with every event).
        key = (status, chunks_done, chunks_total, int(fraction / LINE_STEP + 1e-9))
        if key == self._last_line_key:
            return
        self._last_line_key = key
        suffix = f" ({step})" if step else ""
        print(f"{self.label}: {percent:3d}%{suffix}", file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> ProgressDisplay:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
