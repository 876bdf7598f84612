"""What a job leaves in the artifact store when it ends, besides its images: ``worker.log`` (who rendered
what, in how many attempts and how long) and ``manifest.json`` (the job's final view and every artifact's
size and SHA-256), so that its results outlive the loss of Redis (``JobLifecycle.view`` falls back to the
manifest). Written by ``hgcore.jobs.lifecycle`` before the final status, so a client never misses it.
"""

from __future__ import annotations

import hashlib
import json
import time
from typing import Any

from hgcore.artifacts.keys import job_prefix, manifest_key, worker_log_key
from hgcore.jobs.views import JobView
from hgcore.store.base import ArtifactNotFoundError, ArtifactStore


def worker_log(view: JobView, error: str | None = None) -> bytes:
    """A plain-text log of who rendered what, in how many attempts and how long (and the job's error)."""
    lines = [f"job {view.id} owner={view.owner} spp={view.spp} seed={view.seed} chunks={view.chunks_total}"]
    lines += [
        f"chunk {c.index}: status={c.status} worker={c.worker} attempts={c.attempts} spp={c.spp} "
        f"samples={c.samples} seconds={c.seconds}"
        for c in view.chunks
    ]
    lines += [f"error: {error}"] if error is not None else []
    return ("\n".join(lines) + "\n").encode()


def write_worker_log(store: ArtifactStore, view: JobView, error: str | None = None) -> None:
    store.put_bytes(worker_log_key(view.id), worker_log(view, error))


def artifact_digests(store: ArtifactStore, job_id: str) -> list[dict[str, Any]]:
    """Name, size and SHA-256 of every stored artifact of the job (streamed, never all in memory)."""
    digests = []
    for info in store.list(job_prefix(job_id)):
        if info.key == manifest_key(job_id):
            continue
        sha256 = hashlib.sha256()
        for piece in store.iter_bytes(info.key):
            sha256.update(piece)
        name = info.key.removeprefix(job_prefix(job_id))
        digests.append({"name": name, "size_bytes": info.size_bytes, "sha256": sha256.hexdigest()})
    return digests


def write_manifest(
    store: ArtifactStore,
    view: JobView,
    artifacts: list[dict[str, Any]],
    overrides: dict[str, Any],
    **timing_overrides: float,
) -> None:
    """``manifest.json``: the job's view and its artifacts' digests. ``overrides`` replace view fields and
    ``timing_overrides`` timing fields (the final values, written before the status changes)."""
    job = view.model_dump(mode="json") | overrides
    job["timings"] |= timing_overrides
    manifest = {"job": job, "artifacts": artifacts, "written_at": time.time()}
    store.put_bytes(manifest_key(view.id), json.dumps(manifest, indent=1).encode())


def read_manifest_view(store: ArtifactStore, job_id: str) -> JobView | None:
    """The view kept in the job's ``manifest.json``, or None when there is none (or it is unreadable)."""
    if not job_id.isalnum():
        return None
    try:
        manifest = json.loads(store.get_bytes(manifest_key(job_id)))
    except (ArtifactNotFoundError, ValueError):
        return None
    return JobView.model_validate(manifest["job"])
