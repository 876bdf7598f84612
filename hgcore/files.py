"""Atomic file writes: write beside the target, flush to disk, then ``os.replace`` over it.

A reader (the API, a merge, a second process) sees either the old file or the whole new one, never a
part; a write that fails leaves no temporary file behind.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO


@contextmanager
def atomic_output(path: Path, suffix: str = ".tmp", mode: int | None = None) -> Iterator[Path]:
    """A temporary path in ``path``'s directory that replaces ``path`` when the block succeeds.

    ``suffix`` keeps the file type for writers that go by the name (OpenImageIO); ``mode`` sets the
    permission bits before the file becomes visible (a token file: 0o600)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(handle)
    temporary = Path(name)
    try:
        if mode is not None:
            temporary.chmod(mode)
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def atomic_write_stream(path: Path, write: Callable[[BinaryIO], object], mode: int | None = None) -> None:
    """Call ``write(stream)`` on a temporary file, fsync it, and replace ``path`` with it."""
    with atomic_output(path, mode=mode) as temporary, temporary.open("wb") as stream:
        write(stream)
        stream.flush()
        os.fsync(stream.fileno())


def atomic_write_bytes(path: Path, data: bytes, mode: int | None = None) -> None:
    """Replace ``path`` with ``data`` atomically."""
    atomic_write_stream(path, lambda stream: stream.write(data), mode=mode)
