"""``hgrender serve | worker``: run the service (the commands that talk to it are in ``remote.py``).

``serve`` runs the API (uvicorn) plus ``--workers`` queue workers as child processes (restarted if they
die) and, when ``REDIS_URL`` is unset, a private ``redis-server`` with its data under ``<data dir>/redis``;
it writes a first admin token to ``<data dir>/admin.token``.
"""

from __future__ import annotations

import argparse
import gc
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

from hgcore.redis_clients import redis_client


def register(subparsers: argparse._SubParsersAction) -> None:
    serve = subparsers.add_parser("serve", help="run API + workers (+ private Redis if REDIS_URL is unset)")
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument("--data-dir", type=Path, default=Path("./data"))
    serve.add_argument("--workers", type=int, default=None, help="queue workers (default: cores // 2, min 1)")
    serve.set_defaults(handler=serve_command)

    worker = subparsers.add_parser("worker", help="run one queue worker against REDIS_URL and the store")
    worker.add_argument("--burst", action="store_true", help="exit when the queues are empty")
    worker.add_argument("--name", default=None, help="worker name (default: host name + random suffix)")
    worker.set_defaults(handler=worker_command)


# ---- server side ---------------------------------------------------------------------------------------


def worker_command_line(*extra_args: str) -> list[str]:
    """The command that runs ``hgrender worker`` with this interpreter (no installed script needed)."""
    return [
        sys.executable,
        "-c",
        "import sys; from hgrender.cli import main; sys.exit(main())",
        "worker",
        *extra_args,
    ]


class WorkerSupervisor:
    """Keeps ``count`` ``hgrender worker`` child processes alive (a crashed worker is replaced)."""

    def __init__(self, count: int, env: dict[str, str]) -> None:
        self.count = count
        self.env = env
        self.processes: list[subprocess.Popen[bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._supervise, name="worker-supervisor", daemon=True)

    def _spawn(self) -> subprocess.Popen[bytes]:
        return subprocess.Popen(worker_command_line(), env=self.env)

    def start(self) -> None:
        self.processes = [self._spawn() for _ in range(self.count)]
        self._thread.start()

    def _supervise(self) -> None:
        while not self._stop.wait(1.0):
            for i, process in enumerate(self.processes):
                if process.poll() is not None and not self._stop.is_set():
                    self.processes[i] = self._spawn()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Warm shutdown (SIGTERM: RQ finishes nothing new and exits), SIGKILL after ``timeout_s``."""
        self._stop.set()
        for process in self.processes:
            if process.poll() is None:
                process.terminate()
        for process in self.processes:
            try:
                process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                process.kill()


def _exit_on_signal(signum: int, _frame: object) -> None:
    raise SystemExit(128 + signum)


def serve_command(args: argparse.Namespace) -> int:
    import uvicorn

    from hgcore.settings import Settings
    from service.auth import ensure_admin_token
    from service.main import create_app
    from service.redis_server import RedisServer
    from service.regression.scheduler import start_scheduler_thread

    data_dir: Path = args.data_dir.resolve()
    overrides: dict[str, Any] = {"data_dir": data_dir}
    if args.workers is not None:
        overrides["workers"] = args.workers
    settings = Settings(**overrides)
    redis_server = None
    if not settings.redis_url:
        redis_server = RedisServer(data_dir / "redis").start()
        settings = settings.model_copy(update={"redis_url": redis_server.url})
    try:
        if settings.auth_enabled:
            client = redis_client(settings.redis_url)
            ensure_admin_token(client, data_dir / "admin.token")
            client.close()
            print(f"admin token: {data_dir / 'admin.token'}", file=sys.stderr)
        env = {**os.environ, **settings.to_env()}
        env["HGRENDER_RENDER_THREADS"] = str(settings.render_threads_per_worker)
        supervisor = WorkerSupervisor(settings.worker_count, env)
        supervisor.start()
        # The regression scheduler (issue 7), leader-elected: several `serve` processes fire each run once.
        scheduler = start_scheduler_thread(settings)[0] if settings.regression_scheduler else None
        # uvicorn shuts down gracefully on SIGTERM, then re-raises the signal; with this handler that
        # becomes SystemExit here, so the workers and the private Redis below are stopped too.
        signal.signal(signal.SIGTERM, _exit_on_signal)
        app = create_app(settings)
        # What exists now lives as long as the process: freeze it out of the cyclic collector, whose full
        # passes over these ~10^5 startup objects would otherwise stall requests for tens of ms (p99).
        gc.collect()
        gc.freeze()
        try:
            uvicorn.run(app, host=args.host, port=args.port, log_level="warning", access_log=False)
        finally:
            gc.unfreeze()  # let interpreter shutdown collect them (native bindings check for leaks)
            if scheduler is not None:
                scheduler.stop_event.set()
            # Room for each worker's graceful shutdown: its grace, the heartbeat tick that hands the chunk
            # back, and a few seconds to exit (issue 8).
            supervisor.stop(
                timeout_s=settings.worker_shutdown_grace_s + settings.worker_monitoring_interval_s + 10
            )
    finally:
        if redis_server is not None:
            redis_server.stop()
    return 0


def worker_command(args: argparse.Namespace) -> int:
    from hgcore.settings import Settings
    from worker.queue_worker import run_worker
    from worker.tasks import preload_renderer

    settings = Settings()
    preload_renderer()  # forked work horses inherit the imported renderer
    return run_worker(settings, burst=args.burst, name=args.name)
