"""``hgrender serve`` as users run it: a subprocess (its own process group) with its private Redis."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from service.redis_server import servers_working_in
from tests.support.processes import wait_for


def start_serve(
    data_dir: Path, port: int, workers: int, extra_env: dict[str, str] | None = None
) -> subprocess.Popen[bytes]:
    env = {k: v for k, v in os.environ.items() if k != "REDIS_URL" and not k.startswith("HGRENDER_")}
    env |= extra_env or {}
    command = [
        sys.executable,
        "-c",
        "import sys; from hgrender.cli import main; sys.exit(main())",
        "serve",
        "--port",
        str(port),
        "--data-dir",
        str(data_dir),
        "--workers",
        str(workers),
    ]
    log = (data_dir.parent / f"serve-{port}.log").open("ab")
    # Its own process group, as a shell runs a foreground command (a terminal's Ctrl-C signals the group).
    process = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)

    def ready() -> bool:
        if process.poll() is not None:
            pytest.fail(f"hgrender serve exited: {(data_dir.parent / f'serve-{port}.log').read_text()}")
        try:
            response = httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=1)
        except httpx.HTTPError:
            return False
        # Without workers the service never becomes ready; its API answering is what this waits for.
        return response.status_code == 200 or (workers == 0 and response.json()["checks"]["redis"] == "ok")

    wait_for(ready, 60, "hgrender serve to become ready", interval_s=0.2)
    return process


def stop_serve(process: subprocess.Popen[bytes]) -> None:
    process.send_signal(signal.SIGTERM)
    process.wait(timeout=60)


def redis_servers_in(directory: Path) -> list[int]:
    """PIDs of redis-server processes working in ``directory``."""
    return servers_working_in(directory)
