"""Every Redis key of the job domain, all under ``hgrender:``. ``hgcore.jobs.lifecycle`` owns them: no
other module reads or writes a job's keys (``tests/test_job_lifecycle.py`` checks it).

``job:<id>``            hash: the job record (``record.JobRecord``: owner, status, priority, spp, seed,
                        chunks, timestamps, error)
``job:<id>:scene``      string: the validated scene document (JSON)
``job:<id>:chunks``     hash: the steps' bookkeeping (``record.StepRecord``): ``<i>.<field>`` per chunk
                        (status, progress, worker, attempts, samples, ...) and ``merge.<field>``
``jobs`` / ``jobs:owner:<o>``  sorted sets of ids by creation time (listing, pagination)
``jobs:by_state``       hash: number of jobs in each status (metrics), kept by the transition script
``idempotency:<o>:<k>`` string: the job id an idempotency key of owner ``o`` names
``events:<id>``         pub/sub channel of progress and status events (SSE)
``metrics:*``           counters of rendered samples and render seconds
``reconcile-lock``      held while a reconciliation runs
"""

from __future__ import annotations

JOBS_INDEX = "hgrender:jobs"
JOBS_BY_STATE = "hgrender:jobs:by_state"
RENDER_SECONDS_TOTAL = "hgrender:metrics:render_seconds_total"
SAMPLES_TOTAL = "hgrender:metrics:samples_total"
RECONCILE_LOCK = "hgrender:reconcile-lock"
"""Held while one reconciliation runs (``hgcore.jobs.reconcile``)."""


def job_key(job_id: str) -> str:
    return f"hgrender:job:{job_id}"


def steps_key(job_id: str) -> str:
    return f"hgrender:job:{job_id}:chunks"


def scene_document_key(job_id: str) -> str:
    return f"hgrender:job:{job_id}:scene"


def owner_index_key(owner: str) -> str:
    return f"hgrender:jobs:owner:{owner}"


def idempotency_key(owner: str, key: str) -> str:
    return f"hgrender:idempotency:{owner}:{key}"


def events_channel(job_id: str) -> str:
    return f"hgrender:events:{job_id}"
