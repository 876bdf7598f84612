"""Filesystem artifact store (the default): objects are files under one root directory.

Atomic writes: data goes to a hidden temporary file in the destination directory, is fsynced, and is
renamed over the key with ``os.replace`` (atomic on POSIX within one filesystem).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from hgcore.store.base import ArtifactInfo, ArtifactNotFoundError, ArtifactStore, validate_key


class FilesystemStore(ArtifactStore):
    """Objects are files ``<root>/<key>``."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def path_for(self, key: str) -> Path:
        """The file that holds ``key``."""
        return self.root / validate_key(key)

    def _atomic_write(self, key: str, write: object) -> None:
        target = self.path_for(key)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
        try:
            with os.fdopen(fd, "wb") as out:
                write(out)  # type: ignore[operator]
                out.flush()
                os.fsync(out.fileno())
            os.replace(tmp_name, target)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise

    def put_bytes(self, key: str, data: bytes) -> None:
        self._atomic_write(key, lambda out: out.write(data))

    def put_file(self, key: str, path: Path) -> None:
        with Path(path).open("rb") as source:
            self._atomic_write(key, lambda out: shutil.copyfileobj(source, out, 1 << 20))

    def iter_bytes(self, key: str, chunk_bytes: int = 1 << 20) -> Iterator[bytes]:
        path = self.path_for(key)
        try:
            handle = path.open("rb")
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
            raise ArtifactNotFoundError(key) from None
        with handle:
            while piece := handle.read(chunk_bytes):
                yield piece

    def list(self, prefix: str) -> list[ArtifactInfo]:
        folder_key = prefix.rstrip("/")
        base = self.path_for(folder_key) if folder_key else self.root
        if base.is_file():
            return [ArtifactInfo(folder_key, base.stat().st_size)]
        if not base.is_dir():
            return []
        infos = [
            ArtifactInfo(path.relative_to(self.root).as_posix(), path.stat().st_size)
            for path in base.rglob("*")
            if path.is_file() and not path.name.startswith(".")  # hidden = in-flight temporary files
        ]
        return sorted(infos, key=lambda info: info.key)

    def delete_prefix(self, prefix: str) -> int:
        folder_key = prefix.rstrip("/")
        base = self.path_for(folder_key)
        if base.is_file():
            base.unlink()
            return 1
        if not base.is_dir():
            return 0
        count = sum(1 for path in base.rglob("*") if path.is_file())
        shutil.rmtree(base, ignore_errors=True)
        return count

    def ping(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        if not os.access(self.root, os.W_OK):
            raise OSError(f"store_dir: {self.root} is not writable")
