"""Artifact store interface: job artifacts under ``/``-separated keys (``jobs/<id>/image.exr``).

Every write is atomic: a reader sees either the old object or the complete new one, never a partial file,
and writing a key again (a retried chunk) replaces it rather than adding a duplicate.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from hgcore.errors import InputError

_KEY_SEGMENT = re.compile(r"^[A-Za-z0-9._-]+$")


class ArtifactNotFoundError(KeyError):
    """The store holds no object under this key."""


@dataclass(frozen=True)
class ArtifactInfo:
    """One stored object: its key and size in bytes."""

    key: str
    size_bytes: int


def validate_key(key: str) -> str:
    """Return ``key`` if it is a relative ``/``-path of safe segments (no ``..``), else raise ValueError."""
    segments = key.split("/")
    if not key or any(not _KEY_SEGMENT.match(s) or s in {".", ".."} for s in segments):
        raise InputError(f"key: {key!r} is not a relative path of [A-Za-z0-9._-] segments")
    return key


class ArtifactStore(ABC):
    """Where chunk partials and final artifacts live; shared by the API and all workers."""

    @abstractmethod
    def put_bytes(self, key: str, data: bytes) -> None:
        """Store ``data`` under ``key`` atomically."""

    @abstractmethod
    def put_file(self, key: str, path: Path) -> None:
        """Store the file at ``path`` under ``key`` atomically."""

    @abstractmethod
    def iter_bytes(self, key: str, chunk_bytes: int = 1 << 20) -> Iterator[bytes]:
        """Yield the object's content in pieces; raises ArtifactNotFoundError."""

    @abstractmethod
    def list(self, prefix: str) -> list[ArtifactInfo]:
        """Objects whose key starts with ``prefix`` (a folder, e.g. ``jobs/<id>/``), sorted by key."""

    @abstractmethod
    def delete_prefix(self, prefix: str) -> int:
        """Delete every object under ``prefix``; returns how many were deleted."""

    @abstractmethod
    def ping(self) -> None:
        """Raise if the store cannot be reached."""

    def get_bytes(self, key: str) -> bytes:
        return b"".join(self.iter_bytes(key))

    def get_file(self, key: str, path: Path) -> None:
        """Copy the object to the local file ``path`` (temp file + rename, like every write)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp_path = path.with_name(f".{path.name}.part")
        with tmp_path.open("wb") as out:
            for piece in self.iter_bytes(key):
                out.write(piece)
        tmp_path.replace(path)

    def exists(self, key: str) -> bool:
        validate_key(key)
        return any(info.key == key for info in self.list(key))
