"""What an RQ work horse runs with: the settings its worker process bound before forking it, and temporary
folders named after the horse's pid, so that the worker removes what a killed horse left behind.

The queue worker (``worker.queue_worker``) binds its settings (``bind_settings``) and removes dead horses'
folders; the tasks (``worker.tasks``) read the settings (``bound_settings``) and make their folders
(``horse_work_dir``). Both import this module and never each other.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

from hgcore.settings import Settings

HORSE_TEMP_PREFIX = "hgrender-horse{pid}-"
"""Prefix of the temporary folders of the work horse with process id ``pid``."""

_bound: Settings | None = None


def bind_settings(settings: Settings) -> None:
    """Make ``settings`` the worker process's, for every horse it forks (``worker.queue_worker``)."""
    global _bound
    _bound = settings


def bound_settings() -> Settings:
    """The settings the worker bound (a task runs only in a horse of a worker built by ``build_worker``)."""
    if _bound is None:
        raise RuntimeError("worker.tasks functions run in a work horse of a worker (hgrender worker)")
    return _bound


def horse_work_dir(label: str) -> tempfile.TemporaryDirectory[str]:
    """A temporary folder for one step, named after this work horse's pid: when the horse is killed before
    it could clean up, its worker removes what it left (``remove_horse_temp_dirs``)."""
    return tempfile.TemporaryDirectory(prefix=f"{HORSE_TEMP_PREFIX.format(pid=os.getpid())}{label}-")


def remove_horse_temp_dirs(horse_pid: int) -> None:
    """Delete the temporary folders of the (ended) work horse ``horse_pid``: a horse killed mid-chunk
    (SIGKILL, out of memory, a cancel) cannot run its own clean-up."""
    if horse_pid <= 0:
        return
    for path in Path(tempfile.gettempdir()).glob(HORSE_TEMP_PREFIX.format(pid=horse_pid) + "*"):
        shutil.rmtree(path, ignore_errors=True)


def remove_dead_horse_temp_dirs() -> None:
    """Delete the temporary folders of every work horse on this host that no longer runs (one killed
    together with its worker, which could not clean up after it)."""
    pattern = re.compile(re.escape(HORSE_TEMP_PREFIX).replace(r"\{pid\}", r"(\d+)"))
    for path in Path(tempfile.gettempdir()).glob(HORSE_TEMP_PREFIX.format(pid="*") + "*"):
        match = pattern.match(path.name)
        if match and not Path(f"/proc/{match.group(1)}").exists():
            shutil.rmtree(path, ignore_errors=True)
