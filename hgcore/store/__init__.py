"""Artifact stores: ``FilesystemStore`` (default) and ``S3Store``; ``store_from_settings`` picks one."""

from __future__ import annotations

from hgcore.settings import Settings
from hgcore.store.base import ArtifactInfo, ArtifactNotFoundError, ArtifactStore, validate_key
from hgcore.store.filesystem import FilesystemStore

__all__ = [
    "ArtifactInfo",
    "ArtifactNotFoundError",
    "ArtifactStore",
    "FilesystemStore",
    "store_from_settings",
    "validate_key",
]


def store_from_settings(settings: Settings) -> ArtifactStore:
    """The store the settings name (boto3 is imported only for ``s3``)."""
    if settings.store == "s3":
        from hgcore.store.s3 import S3Store

        assert settings.s3_bucket is not None  # enforced by Settings
        return S3Store(
            settings.s3_bucket,
            settings.s3_prefix,
            endpoint_url=settings.s3_endpoint_url,
            region=settings.s3_region,
        )
    return FilesystemStore(settings.artifact_dir)
