"""Store keys of a job's files: the one place that spells ``jobs/<id>/…``.

A job's directory holds its final artifacts (``layout``'s file names), the uploaded scene bundle under
``input/`` and the chunk partials under ``chunks/`` while the job runs.
"""

from __future__ import annotations

from hgcore.artifacts.layout import CHUNK_PARTIAL_SUFFIX, MANIFEST_JSON, SCENE_JSON, WORKER_LOG


def job_prefix(job_id: str) -> str:
    """Every key of the job starts with this."""
    return f"jobs/{job_id}/"


def artifact_key(job_id: str, name: str) -> str:
    """A file directly in the job's directory (``image.exr``, ``manifest.json``, …)."""
    return job_prefix(job_id) + name


def scene_key(job_id: str) -> str:
    """The validated scene document (provenance, and the worker's input when Redis lost it)."""
    return artifact_key(job_id, SCENE_JSON)


def manifest_key(job_id: str) -> str:
    return artifact_key(job_id, MANIFEST_JSON)


def worker_log_key(job_id: str) -> str:
    return artifact_key(job_id, WORKER_LOG)


def input_prefix(job_id: str) -> str:
    """Uploaded bundle files (USD layers, textures, meshes) live below this."""
    return job_prefix(job_id) + "input/"


def input_key(job_id: str, relative_name: str) -> str:
    return input_prefix(job_id) + relative_name


def chunks_prefix(job_id: str) -> str:
    return job_prefix(job_id) + "chunks/"


def chunk_key(job_id: str, index: int) -> str:
    """A chunk's partial sums (``.npz``)."""
    return f"{chunks_prefix(job_id)}{index}{CHUNK_PARTIAL_SUFFIX}"
