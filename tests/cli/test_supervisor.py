"""``hgrender serve``'s worker supervision: a worker replaced while ``stop()`` begins is stopped too.

Real child processes (``sleep``) stand in for workers; the supervisor's spawn is slowed so that the
replacement of a dead worker overlaps ``stop()``, the window in which a replacement used to be started
after ``stop()`` had listed the workers it terminates, and outlived ``serve``'s Redis.
"""

from __future__ import annotations

import subprocess
import threading
import time

import pytest

from hgrender.cli import service
from hgrender.cli.service import WorkerSupervisor


class SlowSpawnSupervisor(WorkerSupervisor):
    """Spawns ``sleep 60`` children; a respawn (not the first start) signals, then takes 0.5 s."""

    def __init__(self) -> None:
        super().__init__(count=1, env={})
        self.spawned: list[subprocess.Popen[bytes]] = []
        self.respawning = threading.Event()

    def _spawn(self) -> subprocess.Popen[bytes]:
        if self.spawned:
            self.respawning.set()
            time.sleep(0.5)
        process = subprocess.Popen(["sleep", "60"])
        self.spawned.append(process)
        return process


def test_a_worker_replaced_while_stop_begins_is_stopped_too(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(service, "SUPERVISION_INTERVAL_S", 0.05)
    supervisor = SlowSpawnSupervisor()
    supervisor.start()
    try:
        supervisor.spawned[0].kill()
        assert supervisor.respawning.wait(5), "the dead worker was never replaced"
        supervisor.stop(timeout_s=5)  # begins while the replacement is being started
        assert len(supervisor.spawned) == 2
        assert [p.poll() is not None for p in supervisor.spawned] == [True, True]
        time.sleep(0.3)  # and nothing is started after stop()
        assert len(supervisor.spawned) == 2
    finally:
        for process in supervisor.spawned:
            process.kill()
            process.wait()
