"""Job statuses and the state machine: ``queued → running → succeeded | failed``; ``queued | running →
canceled``; a final status never changes (``lifecycle.JobLifecycle.transition`` applies this atomically)."""

from __future__ import annotations

from enum import StrEnum
from typing import Literal


class JobStatus(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELED = "canceled"


TERMINAL_STATUSES: frozenset[JobStatus] = frozenset(
    {JobStatus.SUCCEEDED, JobStatus.FAILED, JobStatus.CANCELED}
)

ALLOWED_FROM: dict[JobStatus, tuple[JobStatus, ...]] = {
    JobStatus.RUNNING: (JobStatus.QUEUED,),
    JobStatus.SUCCEEDED: (JobStatus.QUEUED, JobStatus.RUNNING),
    JobStatus.FAILED: (JobStatus.QUEUED, JobStatus.RUNNING),
    JobStatus.CANCELED: (JobStatus.QUEUED, JobStatus.RUNNING),
}
"""For each target status, the statuses a job may reach it from."""

Priority = Literal["high", "normal", "low"]
"""A job's queue priority."""

StepStatus = Literal["queued", "running", "done", "failed", "canceled"]
"""Status of one step of a job (a chunk, or the merge) in its steps' bookkeeping (``record.StepRecord``)."""

MERGE_PENDING_PROGRESS = 0.999
"""An unfinished job's progress stops here: with every sample rendered its merge step is still to come
(clients show "merging" at this value, not 100 %)."""
