"""A private ``redis-server`` subprocess for the embedded deployment (``hgrender serve`` without REDIS_URL).

Persistence is on (append-only file plus RDB snapshots) under ``<data_dir>/redis`` so job records and
queued chunks survive a restart. The AOF is fsynced before every reply (``appendfsync always``): what a
worker or the API saw acknowledged survives a SIGKILL of the server, so a restart never resumes from a
state up to a second older than what the workers already acted on (a chunk marked done whose completion
the server forgot, a dequeued chunk that is back in no queue). It costs one fsync per write batch, which
the service's write rate (a few per chunk and per progress event) affords. The server listens on
loopback only, on a port chosen free at the first start and kept across restarts (clients reconnect to
the same URL), and ``start`` returns once the server answers PING.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import redis

from hgcore.errors import InputError
from hgcore.redis_clients import redis_client


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def servers_working_in(directory: Path) -> list[int]:
    """PIDs of the redis-server processes whose working directory is ``directory`` (Redis changes into
    its ``--dir``); Linux ``/proc``."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            if (
                proc.name.isdigit()
                and (proc / "comm").read_text().strip() == "redis-server"
                and Path(os.readlink(proc / "cwd")) == directory.resolve()
            ):
                pids.append(int(proc.name))
        except OSError:  # ended meanwhile, or not ours to inspect
            continue
    return pids


def _stop_pid(pid: int, timeout_s: float) -> None:
    """SIGTERM ``pid`` (Redis flushes its AOF and exits), SIGKILL after ``timeout_s``."""
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGTERM)
        deadline = time.monotonic() + timeout_s
        while Path(f"/proc/{pid}").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        if Path(f"/proc/{pid}").exists():
            os.kill(pid, signal.SIGKILL)


class RedisServer:
    """One ``redis-server`` process with its data in ``data_dir``; ``start()``/``stop()`` or a ``with``."""

    def __init__(self, data_dir: Path, port: int | None = None, executable: str = "redis-server") -> None:
        self.data_dir = Path(data_dir)
        self.port = port if port is not None else free_loopback_port()
        self.executable = executable
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def command(self) -> list[str]:
        """The command line: loopback only, AOF on, data and log under ``data_dir``."""
        binary = shutil.which(self.executable)
        if binary is None:
            raise InputError(
                f"executable: {self.executable!r} not found on PATH (Debian: apt install redis-server)"
            )
        return [
            binary,
            "--bind", "127.0.0.1",
            "--port", str(self.port),
            "--dir", str(self.data_dir.resolve()),
            "--appendonly", "yes",
            "--appendfsync", "always",
            "--save", "60 1",
            "--daemonize", "no",
            "--protected-mode", "yes",
            "--logfile", str((self.data_dir / "redis.log").resolve()),
        ]  # fmt: skip

    def start(self, timeout_s: float = 10.0) -> RedisServer:
        """Start the server and wait until it answers PING; raises RuntimeError if it does not. A
        redis-server still running on this data dir (left by a ``serve`` that was SIGKILLed) is stopped
        first: two servers must never append to one AOF."""
        self.data_dir.mkdir(parents=True, exist_ok=True)
        for pid in servers_working_in(self.data_dir):
            _stop_pid(pid, timeout_s)
        # Its own session: a terminal's Ctrl-C reaches `serve`, which stops this server last (its workers
        # hand their chunks back through it first), not this server at once.
        self.process = subprocess.Popen(
            self.command(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
        )
        deadline = time.monotonic() + timeout_s
        client = redis_client(self.url, socket_connect_timeout=0.5)
        try:
            while time.monotonic() < deadline:
                if self.process.poll() is not None:
                    stderr = (
                        self.process.stderr.read().decode(errors="replace") if self.process.stderr else ""
                    )
                    raise RuntimeError(
                        f"redis-server exited with {self.process.returncode}: {stderr.strip()}"
                    )
                try:
                    if client.ping():
                        return self
                except redis.exceptions.RedisError:
                    time.sleep(0.05)
        finally:
            client.close()
        self.stop()
        raise RuntimeError(f"redis-server did not answer PING on port {self.port} within {timeout_s} s")

    def stop(self, timeout_s: float = 10.0) -> None:
        """SIGTERM (Redis flushes the AOF and exits), then SIGKILL if it hangs."""
        if self.process is None or self.process.poll() is not None:
            return
        self.process.terminate()
        try:
            self.process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()

    def __enter__(self) -> RedisServer:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()
