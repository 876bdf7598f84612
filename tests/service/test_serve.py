"""``hgrender serve`` as users run it (a subprocess with its private Redis), restarted with queued jobs,
and the CLI client commands against it."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import stat
from pathlib import Path

import pytest

from hgrender.cli import main as hgrender_main
from hgrender.client import HgrenderClient
from schemas import EXAMPLES_DIR
from service.redis_server import free_loopback_port
from tests.support.processes import children_of, is_alive, wait_for
from tests.support.scenes import tiny_scene
from tests.support.serve import redis_servers_in, start_serve, stop_serve

pytestmark = pytest.mark.slow


def test_serve_restart_keeps_queued_jobs_and_cli_works(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data_dir = tmp_path / "data"
    port = free_loopback_port()
    first = start_serve(data_dir, port, workers=0)  # no workers: jobs stay queued
    try:
        assert redis_servers_in(data_dir / "redis"), "serve started no private Redis"
        token_file = data_dir / "admin.token"
        assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
        token = token_file.read_text().strip()
        with HgrenderClient(f"http://127.0.0.1:{port}", token) as client:
            job_ids = [client.submit(tiny_scene(), chunks=2)["id"] for _ in range(3)]
            assert {client.get(j)["status"] for j in job_ids} == {"queued"}
    finally:
        stop_serve(first)
    assert (data_dir / "redis" / "appendonlydir").is_dir()

    port = free_loopback_port()
    second = start_serve(data_dir, port, workers=1)
    url = f"http://127.0.0.1:{port}"
    try:
        assert token_file.read_text().strip() == token  # the first admin token is kept
        with HgrenderClient(url, token) as client:
            for job_id in job_ids:  # none lost across the restart
                assert client.wait(job_id, timeout_s=180)["status"] == "succeeded"
        common = ["--url", url, "--data-dir", str(data_dir)]
        capsys.readouterr()
        assert hgrender_main(["token", "create", "--owner", "zoe", "--scopes", "submit,read", *common]) == 0
        zoe_token = capsys.readouterr().out.strip()
        zoe = ["--url", url, "--token", zoe_token]
        scene_file = tmp_path / "scene.json"
        scene_file.write_text(json.dumps(tiny_scene()))
        assert hgrender_main(["submit", str(scene_file), "--wait", "--spp", "2", *zoe]) == 0
        out = capsys.readouterr().out.strip().splitlines()
        job_id = out[0]
        assert json.loads(out[-1])["status"] == "succeeded"
        assert hgrender_main(["status", job_id, *zoe]) == 0
        assert json.loads(capsys.readouterr().out)["spp"] == 2
        assert hgrender_main(["list", *zoe]) == 0
        listed = capsys.readouterr().out.strip().splitlines()
        assert len(listed) == 1 and listed[0].startswith(job_id)  # zoe sees only her own job
        assert hgrender_main(["download", job_id, "-o", str(tmp_path / "out"), *zoe]) == 0
        assert (tmp_path / "out" / "image.exr").stat().st_size > 0
        assert hgrender_main(["cancel", job_id, *zoe]) == 2  # already succeeded: 409, reported
        assert "409" in capsys.readouterr().err
        assert sorted(EXAMPLES_DIR.glob("*.json"))
    finally:
        stop_serve(second)
    # Both serve runs stopped their private Redis (a redis-server's working directory is its data dir).
    assert wait_for(lambda: not redis_servers_in(data_dir / "redis"), 10, "the private Redis to stop")


def test_a_sigkilled_serve_leaves_no_worker_and_its_redis_is_replaced(tmp_path: Path) -> None:
    """Workers shut down when their `serve` dies; the Redis it leaves behind is stopped by the next
    `serve` on the same data dir before it starts its own (one AOF, one writer), and the jobs live on."""
    data_dir = tmp_path / "data"
    port = free_loopback_port()
    first = start_serve(data_dir, port, workers=1)
    workers = [p for p in children_of(first.pid) if b"worker" in Path(f"/proc/{p}/cmdline").read_bytes()]
    assert len(workers) == 1
    token = (data_dir / "admin.token").read_text().strip()
    with HgrenderClient(f"http://127.0.0.1:{port}", token) as client:
        job_id = client.submit(tiny_scene(), chunks=2)["id"]
    (old_redis,) = redis_servers_in(data_dir / "redis")
    first.kill()
    first.wait()
    second = None
    try:
        wait_for(lambda: not any(is_alive(p) for p in workers), 30, "the orphaned worker to shut down")
        second = start_serve(data_dir, port, workers=1)
        assert not is_alive(old_redis)
        assert len(redis_servers_in(data_dir / "redis")) == 1
        with HgrenderClient(f"http://127.0.0.1:{port}", token) as client:
            assert client.wait(job_id, timeout_s=120)["status"] == "succeeded"
    finally:
        if second is not None:
            stop_serve(second)
        for pid in [*workers, *redis_servers_in(data_dir / "redis")]:  # whatever a failure left behind
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_ctrl_c_stops_serve_in_order_without_restarting_redis_or_a_traceback(tmp_path: Path) -> None:
    """A terminal's Ctrl-C sends SIGINT to serve's whole process group. Serve alone gets it (its workers
    and private Redis run in sessions of their own) and stops the scheduler, then the workers, then
    Redis: before, Redis died with the group at once, serve restarted it during its own shutdown, and
    the regression scheduler's thread died with a ConnectionError traceback."""
    data_dir = tmp_path / "data"
    port = free_loopback_port()
    serve = start_serve(data_dir, port, workers=1)
    workers = children_of(serve.pid)
    redis_pids = redis_servers_in(data_dir / "redis")
    assert len(redis_pids) == 1
    try:
        os.killpg(serve.pid, signal.SIGINT)
        assert serve.wait(timeout=60) == 128 + signal.SIGINT
    finally:
        for pid in [*workers, *redis_servers_in(data_dir / "redis")]:  # whatever a failure left behind
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    log = (tmp_path / f"serve-{port}.log").read_text()
    assert "restarting" not in log, log
    assert "Traceback" not in log, log
    assert "shutting down" in log, log
    assert not [p for p in [*workers, *redis_pids] if is_alive(p)]
