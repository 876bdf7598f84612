"""The scheduler fires each due time exactly once: two processes against one Redis, and a leader killed
around a due time and replaced.

Real processes (``hgrender scheduler``) on the session's private Redis; a 2 s interval schedule stands in
for a per-minute one (time compressed 30×; the logic does not depend on the period). The leader lease is
1.5 s, so a standby takes over within 1.5 s + its 0.5 s polling. Runs create render jobs that stay queued
(no workers), which is all that counts here: one run record per due time.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import redis

from hgcore.regression.models import ScheduleCreate, Suite, SuiteScene
from hgcore.regression.store import RegressionStore
from hgcore.settings import Settings
from hgcore.store import store_from_settings
from hgrender.cli.service import worker_command_line
from service.redis_server import RedisServer
from tests.support.processes import wait_for

INTERVAL_S = 2


@pytest.fixture()
def settings(redis_url: str, tmp_path: Path) -> Iterator[Settings]:
    client = redis.Redis.from_url(redis_url)
    client.flushdb()
    client.close()
    yield Settings(redis_url=redis_url, data_dir=tmp_path, regression_leader_ttl_s=1.5)


def start_scheduler(settings: Settings, name: str) -> subprocess.Popen[bytes]:
    command = [*worker_command_line()[:-1], "scheduler", "--name", name]  # this interpreter, no script
    log = (settings.data_dir / f"{name}.log").open("wb")
    return subprocess.Popen(
        command, env={**os.environ, **settings.to_env()}, stdout=log, stderr=subprocess.STDOUT
    )


def stop(process: subprocess.Popen[bytes], kill: bool = False) -> None:
    if process.poll() is None:
        process.send_signal(signal.SIGKILL if kill else signal.SIGTERM)
    process.wait(timeout=30)


def make_schedule(settings: Settings) -> tuple[RegressionStore, str, float]:
    client = redis.Redis.from_url(settings.redis_url or "")
    store = RegressionStore(client, store_from_settings(settings))
    suite = Suite(scenes=[SuiteScene(example="cornell_box", spp=1, width=8, height=8)])
    view = store.create_schedule(ScheduleCreate(name="every 2 s", interval_s=INTERVAL_S, suite=suite), "ci")
    return store, view.id, view.created_at


def due_times(store: RegressionStore, schedule_id: str) -> list[float]:
    return sorted(run.due_at for run in store.list_runs(schedule_id, 1000) if run.due_at is not None)


def assert_every_due_time_once(times: list[float], created_at: float, expected_at_least: int) -> None:
    # Due times are created_at + k·interval, k = 1, 2, ...: consecutive k, none twice, none missing.
    steps = [round((t - created_at) / INTERVAL_S, 6) for t in times]
    assert steps == [float(k) for k in range(1, len(steps) + 1)], steps
    assert len(steps) >= expected_at_least


def test_two_schedulers_fire_each_due_time_once(settings: Settings) -> None:
    store, schedule_id, created_at = make_schedule(settings)
    processes = [start_scheduler(settings, "sched-a"), start_scheduler(settings, "sched-b")]
    try:
        time.sleep(5 * INTERVAL_S + 1.0)
    finally:
        for process in processes:
            stop(process)
    times = due_times(store, schedule_id)
    # The first due time is created_at + 2 s; by 11 s at least 4 (start-up of the processes takes ~1-2 s).
    assert_every_due_time_once(times, created_at, expected_at_least=4)


def test_killed_leader_is_replaced_without_losing_or_duplicating_a_due_time(settings: Settings) -> None:
    store, schedule_id, created_at = make_schedule(settings)
    leader = start_scheduler(settings, "sched-leader")
    try:
        wait_for(lambda: len(due_times(store, schedule_id)) >= 2, 30, "the leader to fire", interval_s=0.05)
        # Kill it right after a due time, stay down past the next one, then start a replacement.
        stop(leader, kill=True)
        fired_before = len(due_times(store, schedule_id))
        time.sleep(INTERVAL_S + 1.0)
        assert len(due_times(store, schedule_id)) == fired_before  # nobody fired while down
        replacement = start_scheduler(settings, "sched-replacement")
        try:
            time.sleep(3 * INTERVAL_S + 2.0)
        finally:
            stop(replacement)
    finally:
        stop(leader, kill=True)
    times = due_times(store, schedule_id)
    # The due time missed while down (within the misfire grace) is run late, once; the rest on time.
    assert_every_due_time_once(times, created_at, expected_at_least=fired_before + 3)


def test_pause_skips_due_times_and_resume_continues_on_the_grid(settings: Settings) -> None:
    store, schedule_id, created_at = make_schedule(settings)
    scheduler = start_scheduler(settings, "sched-pause")
    try:
        wait_for(lambda: due_times(store, schedule_id), 30, "the first due time", interval_s=0.05)
        store.set_paused(schedule_id, True)
        paused_at = time.time()
        time.sleep(1.0)  # the leader re-syncs within SYNC_INTERVAL_S = 1 s
        fired_while_pausing = len(due_times(store, schedule_id))
        time.sleep(2 * INTERVAL_S + 0.5)
        assert len(due_times(store, schedule_id)) == fired_while_pausing  # nothing while paused
        store.set_paused(schedule_id, False)
        resumed_at = time.time()
        time.sleep(2 * INTERVAL_S + 1.0)
    finally:
        stop(scheduler)
    times = due_times(store, schedule_id)
    steps = [(t - created_at) / INTERVAL_S for t in times]
    assert all(abs(step - round(step)) < 1e-6 for step in steps), steps  # still on created_at + k·interval
    after = [t for t in times if t > paused_at + 1.0]
    assert after and all(t > resumed_at for t in after)  # the pause's due times were skipped, not caught up
    assert len(set(times)) == len(times)


def test_a_redis_restart_under_a_running_scheduler_is_stood_out_not_fatal(tmp_path: Path) -> None:
    """The private Redis of ``hgrender serve`` restarts (it died, serve starts it again on the same port
    and data dir): the scheduler logs one line, stands by, leads again once Redis answers, and the due
    times go on, each once. Before, the first ``ConnectionError`` ended the scheduler with a traceback."""
    server = RedisServer(tmp_path / "redis").start()
    settings = Settings(redis_url=server.url, data_dir=tmp_path, regression_leader_ttl_s=1.5)
    store, schedule_id, created_at = make_schedule(settings)
    scheduler = start_scheduler(settings, "sched-outage")
    try:
        # Kill Redis between due times, not inside one: a run whose claim is made but whose creation
        # Redis cuts short is logged and not retried (a second attempt could create a second run).
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            times = due_times(store, schedule_id)
            if times and 0.2 < time.time() - times[-1] < 0.8 * INTERVAL_S:  # caught up, next one ahead
                break
            time.sleep(0.02)
        assert due_times(store, schedule_id), "the scheduler never fired"
        assert server.process is not None
        server.process.kill()  # appendfsync always: everything acknowledged is in the AOF
        server.process.wait()
        time.sleep(INTERVAL_S + 1.0)  # down across a due time
        assert scheduler.poll() is None, "the scheduler exited when Redis went away"
        server = RedisServer(tmp_path / "redis", port=server.port).start()
        fired_after_restart = len(due_times(store, schedule_id))
        time.sleep(3 * INTERVAL_S + 2.0)
        assert scheduler.poll() is None
    finally:
        stop(scheduler)
        server.stop()
    log = (tmp_path / "sched-outage.log").read_text()
    assert "Traceback" not in log, log
    assert log.count("Redis unavailable") == 1, log
    assert "Redis answers again" in log, log
    server = RedisServer(tmp_path / "redis", port=server.port).start()  # same port: `store` reconnects
    try:
        times = due_times(store, schedule_id)
    finally:
        server.stop()
    # The due time missed while Redis was down is run late (misfire grace), once; the rest on time.
    assert len(times) >= fired_after_restart + 3
    assert_every_due_time_once(times, created_at, expected_at_least=3)
