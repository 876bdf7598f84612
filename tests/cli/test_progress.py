"""The progress display: on a terminal a bar that shows status and chunk counts; without one, one line per
step (status, chunks or another 10 %), never carriage-return redraws."""

from __future__ import annotations

import io

from hgrender.cli.progress import ProgressDisplay


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_terminal_bar_shows_status_and_chunk_counts() -> None:
    stream = Terminal()
    with ProgressDisplay("job 3f2a", stream=stream) as display:
        display.update(0.5, "running", 2, 4, 3.0)
    last_frame = stream.getvalue().rstrip("\n").split("\r")[-1]
    assert last_frame.startswith("job 3f2a:  50%|")
    assert "| running, 2/4 chunks, eta 3 s [" in last_frame


def test_without_a_terminal_one_line_per_step() -> None:
    stream = io.StringIO()
    with ProgressDisplay("job 3f2a", stream=stream) as display:
        display.update(0.0, "queued", 0, 4, None)
        display.update(0.01, "running", 0, 4, 9.0)
        display.update(0.02, "running", 0, 4, 8.0)  # same step: only the ETA moved
        display.update(0.26, "running", 1, 4, 6.0)
        display.update(1.0, "succeeded", 4, 4, None)
    assert "\r" not in stream.getvalue()
    assert stream.getvalue().splitlines() == [
        "job 3f2a:   0% (queued, 0/4 chunks)",
        "job 3f2a:   1% (running, 0/4 chunks, eta 9 s)",
        "job 3f2a:  26% (running, 1/4 chunks, eta 6 s)",
        "job 3f2a: 100% (succeeded, 4/4 chunks)",
    ]


def test_a_running_job_with_every_sample_rendered_says_merging_not_100_percent() -> None:
    """The service caps an unfinished job's progress at 0.999 while its merge step runs: the display
    rounds down and names the step, so 100 % is only ever shown for a finished job."""
    stream = io.StringIO()
    with ProgressDisplay("job 3f2a", stream=stream) as display:
        display.update(0.5, "running", 1, 2, 4.0)
        display.update(0.999, "running", 1, 2, 0.0)
        display.update(1.0, "succeeded", 2, 2, None)
    assert stream.getvalue().splitlines() == [
        "job 3f2a:  50% (running, 1/2 chunks, eta 4 s)",
        "job 3f2a:  99% (merging: all samples rendered, writing the image)",
        "job 3f2a: 100% (succeeded, 2/2 chunks)",
    ]
    terminal = Terminal()
    with ProgressDisplay("job 3f2a", stream=terminal) as display:
        display.update(0.999, "running", 1, 2, 0.0)
    last_frame = terminal.getvalue().rstrip("\n").split("\r")[-1]
    assert last_frame.startswith("job 3f2a:  99%|") and "| merging: all samples rendered" in last_frame
