"""``hgrender serve | worker``: run the service (the commands that talk to it are in ``remote.py``).

``serve`` runs the API (uvicorn) plus ``--workers`` queue workers as child processes and, when
``REDIS_URL`` is unset, a private ``redis-server`` with its data under ``<data dir>/redis``; it supervises
both (a dead worker or Redis is restarted, with bounded back-off; after a Redis restart, and at start, the
jobs' queue state is reconciled) and writes a first admin token to ``<data dir>/admin.token``. It checks
that its port is free before it creates anything, and prints where it listens.
"""

from __future__ import annotations

import argparse
import gc
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from hgrender.cli import CliError


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
    worker.add_argument(
        "--exit-with",
        type=int,
        default=None,
        metavar="PID",
        help="warm-shut down when process PID, this worker's parent, dies (hgrender serve passes its own)",
    )
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


log = logging.getLogger("hgrender.serve")

SUPERVISION_INTERVAL_S = 0.5
RESTART_BACKOFF_S = (0.5, 1.0, 2.0, 5.0, 10.0)
"""Waits before successive restarts of a child that keeps dying; reset once it has run ``STABLE_S``."""
STABLE_S = 30.0


class RestartBackoff:
    """When a supervised child may be restarted: at once after its first death, then after growing waits
    while it keeps dying soon after each start (no crash loop that burns the CPU)."""

    def __init__(self) -> None:
        self.failures = 0
        self.started_s = time.monotonic()
        self.not_before_s = 0.0

    def died(self) -> None:
        if time.monotonic() - self.started_s > STABLE_S:
            self.failures = 0
        delay_s = RESTART_BACKOFF_S[min(self.failures, len(RESTART_BACKOFF_S) - 1)] if self.failures else 0.0
        self.not_before_s = time.monotonic() + delay_s
        self.failures += 1

    def may_start(self) -> bool:
        return time.monotonic() >= self.not_before_s

    def restarted(self) -> None:
        self.started_s = time.monotonic()


class WorkerSupervisor:
    """Keeps ``count`` ``hgrender worker`` child processes alive (a dead worker is replaced, with bounded
    back-off if it keeps dying)."""

    def __init__(self, count: int, env: dict[str, str]) -> None:
        self.count = count
        self.env = env
        self.processes: list[subprocess.Popen[bytes]] = []
        self._backoffs = [RestartBackoff() for _ in range(count)]
        self._stop = threading.Event()
        # Held while a worker is replaced and while stop() begins: no replacement may start after stop()
        # has listed the workers it terminates and waits for (it would outlive serve's Redis).
        self._spawning = threading.Lock()
        self._thread = threading.Thread(target=self._supervise, name="worker-supervisor", daemon=True)

    def _spawn(self) -> subprocess.Popen[bytes]:
        # A worker outlives no `serve` (not even a SIGKILLed one): it shuts down when its parent dies.
        # Its own session keeps a terminal's Ctrl-C (SIGINT to the whole foreground group) from reaching
        # it beside serve's SIGTERM: two signals would make RQ's shutdown a cold one.
        return subprocess.Popen(
            worker_command_line("--exit-with", str(os.getpid())), env=self.env, start_new_session=True
        )

    def start(self) -> None:
        self.processes = [self._spawn() for _ in range(self.count)]
        self._thread.start()

    def _supervise(self) -> None:
        dead: set[int] = set()
        while not self._stop.wait(SUPERVISION_INTERVAL_S):
            for i, process in enumerate(self.processes):
                with self._spawning:
                    if process.poll() is None or self._stop.is_set():
                        continue
                    if i not in dead:
                        log.warning(
                            "worker pid %d exited with %s; restarting it", process.pid, process.returncode
                        )
                        self._backoffs[i].died()
                        dead.add(i)
                    if self._backoffs[i].may_start():
                        self.processes[i] = self._spawn()
                        self._backoffs[i].restarted()
                        dead.discard(i)
        # Linux signals a child's parent death when the *thread* that started it ends: this thread stays
        # (parked, a daemon) so the workers it restarted are not told to stop twice (a cold shutdown).
        threading.Event().wait()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Warm shutdown (SIGTERM: RQ finishes nothing new and exits), SIGKILL after ``timeout_s``."""
        with self._spawning:
            self._stop.set()
        for process in self.processes:
            if process.poll() is None:
                process.terminate()
        for process in self.processes:
            try:
                process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                process.kill()


class RedisSupervisor:
    """Restarts the private Redis when it dies (same port, same data dir: its AOF restores every job),
    with bounded back-off, then reconciles the jobs' queue state (``hgcore.jobs.reconcile``). ``stop()``
    ends the supervision only: ``serve`` calls it when its shutdown begins, so that a Redis ending then is
    not started again, and stops the server itself after the workers."""

    def __init__(self, server: Any, settings: Any) -> None:
        self.server = server
        self.settings = settings
        self.restarts = 0
        self._backoff = RestartBackoff()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._supervise, name="redis-supervisor", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _supervise(self) -> None:
        while not self._stop.wait(SUPERVISION_INTERVAL_S):
            process = self.server.process
            if process is None or process.poll() is None:
                continue
            log.warning("private redis-server exited with %s; restarting it", process.returncode)
            self._backoff.died()
            while not self._backoff.may_start():
                if self._stop.wait(SUPERVISION_INTERVAL_S):
                    return
            try:
                self.server.start()
            except RuntimeError as error:  # e.g. the port was taken meanwhile: try again after back-off
                log.error("restarting redis-server failed: %s", error)
                continue
            self._backoff.restarted()
            self.restarts += 1
            reconcile(self.settings)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)


def reconcile(settings: Any, confirm_after_s: float = 2.0) -> None:
    """Re-enqueue whatever the queue state lost track of (``hgcore.jobs.reconcile``), logging each."""
    from hgcore.jobs.lifecycle import JobLifecycle
    from hgcore.jobs.reconcile import QueueReconciler
    from hgcore.redis_clients import redis_client
    from hgcore.store import store_from_settings

    client = redis_client(settings.redis_url)
    try:
        lifecycle = JobLifecycle(client, store_from_settings(settings))
        revived = QueueReconciler(lifecycle, settings).reconcile(confirm_after_s)
    except Exception as error:  # Redis gone again: the next restart reconciles
        log.error("reconciliation failed: %s", error)
        return
    finally:
        client.close()
    for rq_id, reason in revived.items():
        log.warning("re-enqueued %s (%s)", rq_id, reason)


def ensure_port_free(host: str, port: int) -> None:
    """Raise CliError when ``host:port`` cannot be bound (another server listens there), before anything
    is created on disk."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn binds
        try:
            sock.bind((host, port))
        except OSError as error:
            raise CliError(
                f"port: cannot listen on {host}:{port} ({error.strerror}); is another hgrender serve "
                "running there? Choose another with --port"
            ) from None


def _exit_on_signal(signum: int, _frame: object) -> None:
    raise SystemExit(128 + signum)


SHUTDOWN_SIGNALS = (signal.SIGTERM, signal.SIGINT)
"""uvicorn shuts down gracefully on these, then re-raises the signal; ``_exit_on_signal`` turns that into
SystemExit (no KeyboardInterrupt traceback for a Ctrl-C), so the workers and the private Redis are stopped
in order by ``serve_command``'s ``finally``."""


def serve_command(args: argparse.Namespace) -> int:
    import uvicorn

    from hgcore.redis_clients import redis_client
    from hgcore.settings import Settings
    from service.auth import ensure_admin_token
    from service.main import create_app
    from service.redis_server import RedisServer
    from service.regression.scheduler import start_scheduler_thread

    ensure_port_free(args.host, args.port)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    data_dir: Path = args.data_dir.resolve()
    overrides: dict[str, Any] = {"data_dir": data_dir}
    if args.workers is not None:
        overrides["workers"] = args.workers
    settings = Settings(**overrides)
    redis_server = redis_supervisor = None
    if not settings.redis_url:
        redis_server = RedisServer(data_dir / "redis").start()
        settings = settings.model_copy(update={"redis_url": redis_server.url})
    try:
        token_file = data_dir / "admin.token"
        if settings.auth_enabled:
            client = redis_client(settings.redis_url)
            ensure_admin_token(client, token_file)
            client.close()
        # With its private Redis no worker runs yet, so nothing is in flight and one look suffices.
        reconcile(settings, confirm_after_s=0.0 if redis_server is not None else 2.0)
        if redis_server is not None:
            redis_supervisor = RedisSupervisor(redis_server, settings)
            redis_supervisor.start()
        _print_where(args.host, args.port, settings, token_file if settings.auth_enabled else None)
        env = {**os.environ, **settings.to_env()}
        env["HGRENDER_RENDER_THREADS"] = str(settings.render_threads_per_worker)
        supervisor = WorkerSupervisor(settings.worker_count, env)
        supervisor.start()
        # The regression scheduler (issue 7), leader-elected: several `serve` processes fire each run once.
        scheduler = start_scheduler_thread(settings)[0] if settings.regression_scheduler else None
        for signum in SHUTDOWN_SIGNALS:
            signal.signal(signum, _exit_on_signal)
        app = create_app(settings)
        # What exists now lives as long as the process: freeze it out of the cyclic collector, whose full
        # passes over these ~10^5 startup objects would otherwise stall requests for tens of ms (p99).
        gc.collect()
        gc.freeze()
        try:
            uvicorn.run(app, host=args.host, port=args.port, log_level="warning", access_log=False)
        finally:
            gc.unfreeze()  # let interpreter shutdown collect them (native bindings check for leaks)
            log.info("shutting down: regression scheduler, workers, then the private Redis")
            if redis_supervisor is not None:
                redis_supervisor.stop()  # the workers still need Redis, but it is not restarted any more
            if scheduler is not None:
                scheduler.stop_event.set()
            # Room for each worker's graceful shutdown: its grace, the heartbeat tick that hands the chunk
            # back, and a few seconds to exit (issue 8).
            supervisor.stop(
                timeout_s=settings.worker_shutdown_grace_s + settings.worker_monitoring_interval_s + 10
            )
    finally:
        if redis_supervisor is not None:
            redis_supervisor.stop()
        if redis_server is not None:
            redis_server.stop()
    return 0


def _print_where(host: str, port: int, settings: Any, token_file: Path | None) -> None:
    """Where the service listens and keeps its state (stdout, flushed: read by people and scripts)."""
    url = f"http://{f'[{host}]' if ':' in host else host}:{port}"
    redis_line = (
        f"private, {settings.redis_url}" if settings.redis_url.startswith("redis://127.") else "external"
    )
    lines = [
        f"hgrender serve: API      {url}",
        f"hgrender serve: viewer   {url}/",
        f"hgrender serve: API docs {url}/docs",
        f"hgrender serve: token    {token_file if token_file is not None else 'none (HGRENDER_AUTH=off)'}",
        f"hgrender serve: data dir {settings.data_dir}",
        f"hgrender serve: redis    {redis_line}",
    ]
    print("\n".join(lines), flush=True)


def worker_command(args: argparse.Namespace) -> int:
    from hgcore.settings import Settings
    from worker.preload import preload_renderer
    from worker.queue_worker import run_worker

    if args.exit_with is not None:
        from worker.queue_worker import die_with_parent

        if not die_with_parent(signal.SIGTERM, args.exit_with):
            raise CliError(f"exit-with: process {args.exit_with} is not this worker's parent (any more)")
    settings = Settings()
    preload_renderer(settings)  # forked work horses inherit the imported renderer
    return run_worker(settings, burst=args.burst, name=args.name)
