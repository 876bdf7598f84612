"""The regression scheduler: APScheduler 3 with a Redis job store, one leader, one run per due time.

* Leader election: any number of scheduler processes may run; the one holding the Redis lease
  ``hgrender:regression:scheduler:leader`` (SET NX PX, renewed every ttl/3, compare-and-renew in Lua) runs
  APScheduler's ``BackgroundScheduler``; the others wait and take over at most ``regression_leader_ttl_s``
  after the leader dies. A leader whose renewal fails (it was paused past the lease) stops its scheduler at
  once; in the moment both may run, the due-time claims below keep every run unique.
* Schedules (``hgcore.regression.store``) are the source of truth; the leader mirrors them into APScheduler
  jobs (cron: ``CronTrigger.from_crontab`` in the schedule's time zone; interval: ``IntervalTrigger`` anchored
  at the schedule's creation time, so every process computes the same due times). Next run times persist in
  the ``RedisJobStore``, so a new leader resumes where the old one stopped.
* Exactly once: the executor claims each (schedule, due time) in Redis, under its own name, before it
  creates the run. A due time fired by a dying leader that had not yet saved its next run time is offered
  again by its successor and refused by the claim, so restarts never duplicate. A claim that meets a Redis
  outage is retried until Redis answers (the same name may claim again, in case only the reply was lost),
  so an outage delays due times instead of losing them.
* A Redis outage ends a term as leader, never the scheduler: it stands by and leads again when Redis
  answers (``RegressionScheduler.run``).
* Misfire policy: ``coalesce=False`` and ``misfire_grace_time = regression_misfire_grace_s``: after an
  outage every missed due time younger than the grace is run once (oldest first); older ones are skipped and
  logged (APScheduler's EVENT_JOB_MISSED). A paused schedule skips the due times of its pause.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
import uuid
from datetime import UTC, datetime, timedelta
from typing import Any

import redis
from apscheduler.events import EVENT_JOB_EXECUTED, EVENT_JOB_MISSED, JobExecutionEvent
from apscheduler.executors.base import BaseExecutor
from apscheduler.job import Job
from apscheduler.jobstores.redis import RedisJobStore
from apscheduler.schedulers.background import BackgroundScheduler
from apscheduler.triggers.base import BaseTrigger
from apscheduler.triggers.cron import CronTrigger
from apscheduler.triggers.interval import IntervalTrigger
from redis.connection import parse_url

from hgcore.errors import InputError
from hgcore.redis_clients import redis_client
from hgcore.regression.models import ScheduleView
from hgcore.regression.store import RegressionStore
from hgcore.settings import Settings
from service.regression.runs import RunService, run_service_for

LEADER_KEY = "hgrender:regression:scheduler:leader"
JOBS_KEY = "hgrender:regression:apscheduler:jobs"
RUN_TIMES_KEY = "hgrender:regression:apscheduler:run_times"
CLAIM_RETRY_CAP_S = 2.0
"""Longest wait between two attempts at a due time's claim while Redis is unreachable."""
SYNC_INTERVAL_S = 1.0
"""How often the leader re-reads the schedules' version counter (new, paused, deleted schedules)."""

_RENEW_LUA = """
if redis.call('GET', KEYS[1]) == ARGV[1] then return redis.call('PEXPIRE', KEYS[1], ARGV[2]) end
return 0
"""
_RELEASE_LUA = """
if redis.call('GET', KEYS[1]) == ARGV[1] then return redis.call('DEL', KEYS[1]) end
return 0
"""

log = logging.getLogger(__name__)


def fire_placeholder(schedule_id: str) -> None:
    """The callable APScheduler stores with each job; ``ClaimingExecutor`` fires runs instead of calling it
    (it needs the due time, which APScheduler does not pass to job functions)."""
    raise RuntimeError(f"schedule {schedule_id}: jobs run through ClaimingExecutor only")


def trigger_for(schedule: ScheduleView) -> BaseTrigger:
    """The APScheduler trigger of a schedule (same due times in every process)."""
    if schedule.cron is not None:
        return CronTrigger.from_crontab(schedule.cron, timezone=schedule.timezone)
    assert schedule.interval_s is not None
    start = datetime.fromtimestamp(schedule.created_at, UTC) + timedelta(seconds=schedule.interval_s)
    return IntervalTrigger(seconds=schedule.interval_s, start_date=start, timezone=UTC)


class ClaimingExecutor(BaseExecutor):
    """Fires each due time of a job once across all processes: claim, then start the run.

    A claim that fails because Redis is unreachable is retried (back-off up to ``CLAIM_RETRY_CAP_S``)
    until Redis answers or the scheduler stops: APScheduler moves on to the next due time whatever the
    executor does, so a claim given up here would lose its due time for good."""

    def __init__(self, runs: RunService, claimer: str, stop_event: threading.Event) -> None:
        super().__init__()
        self.runs = runs
        self.claimer = claimer
        self.stop_event = stop_event

    def _do_submit_job(self, job: Job, run_times: list[datetime]) -> None:
        events = []
        for run_time in run_times:
            late = datetime.now(UTC) - run_time
            if job.misfire_grace_time is not None and late > timedelta(seconds=job.misfire_grace_time):
                log.warning("schedule %s: due time %s missed by %s; skipped", job.id, run_time, late)
                events.append(
                    JobExecutionEvent(EVENT_JOB_MISSED, job.id, self._jobstore_alias(job), run_time)
                )
                continue
            try:
                self._claim_and_fire(job.id, run_time.timestamp())
            except Exception as error:  # one failing schedule must not stop the others
                log.exception("schedule %s: run at %s not started", job.id, run_time)
                self._run_job_error(job.id, error)
                return
            events.append(JobExecutionEvent(EVENT_JOB_EXECUTED, job.id, self._jobstore_alias(job), run_time))
        self._run_job_success(job.id, events)

    def _claim_and_fire(self, schedule_id: str, due_at: float) -> None:
        wait_s = 0.1
        while True:
            try:
                claimed = self.runs.regression.claim_due_time(schedule_id, due_at, self.claimer)
                break
            except redis.RedisError:
                if self.stop_event.wait(wait_s):
                    raise
                wait_s = min(2 * wait_s, CLAIM_RETRY_CAP_S)
        if claimed:
            # After the claim a failure is not retried: the run may be half-created, and a second one
            # would break "one run per due time". It is logged by the caller.
            start_due_run(self.runs, schedule_id, due_at)

    @staticmethod
    def _jobstore_alias(job: Job) -> str:
        return getattr(job, "_jobstore_alias", "default")


def start_due_run(runs: RunService, schedule_id: str, due_at: float) -> None:
    """Start the run of ``schedule_id`` for ``due_at`` (its claim is this process's)."""
    schedule = runs.regression.get_schedule(schedule_id)
    runs.start_run(
        schedule.suite,
        schedule.owner,
        trigger="schedule",
        schedule_id=schedule_id,
        due_at=due_at,
        webhook_url=str(schedule.webhook_url) if schedule.webhook_url else None,
    )
    log.info("schedule %s: started the run due at %s", schedule_id, datetime.fromtimestamp(due_at, UTC))


def next_run_times(client: redis.Redis) -> dict[str, float]:
    """Next due time (Unix s) of every scheduled, unpaused job, as the job store holds it."""
    return {k.decode(): float(v) for k, v in client.zrange(RUN_TIMES_KEY, 0, -1, withscores=True)}


class RegressionScheduler:
    """One scheduler process: waits for the leader lease, then runs APScheduler until it loses it."""

    def __init__(self, settings: Settings, name: str | None = None) -> None:
        if not settings.redis_url:
            raise InputError("redis_url: the scheduler needs the deployment's Redis (REDIS_URL)")
        self.settings = settings
        self.name = name or f"scheduler-{uuid.uuid4().hex[:8]}"
        self.client = redis_client(settings.redis_url)
        self.runs = run_service_for(self.client, settings)
        self.regression: RegressionStore = self.runs.regression
        self.ttl_ms = int(settings.regression_leader_ttl_s * 1000)
        self._renew = self.client.register_script(_RENEW_LUA)
        self._release = self.client.register_script(_RELEASE_LUA)
        self.stop_event = threading.Event()

    def try_acquire(self) -> bool:
        return bool(self.client.set(LEADER_KEY, self.name, nx=True, px=self.ttl_ms))

    def renew(self) -> bool:
        return bool(self._renew(keys=[LEADER_KEY], args=[self.name, self.ttl_ms]))

    def release(self) -> None:
        self._release(keys=[LEADER_KEY], args=[self.name])

    def _build_scheduler(self) -> BackgroundScheduler:
        jobstore = RedisJobStore(
            jobs_key=JOBS_KEY, run_times_key=RUN_TIMES_KEY, **_connect_args(self.settings)
        )
        return BackgroundScheduler(
            jobstores={"default": jobstore},
            executors={"default": ClaimingExecutor(self.runs, self.name, self.stop_event)},
            job_defaults={
                "coalesce": False,
                "misfire_grace_time": self.settings.regression_misfire_grace_s,
                "max_instances": 1,
            },
            timezone=UTC,
        )

    def sync(self, scheduler: BackgroundScheduler) -> None:
        """Mirror the stored schedules into APScheduler jobs (add new, pause/resume, remove deleted)."""
        schedules = {s.id: s for s in self.regression.list_schedules()}
        jobs = {job.id: job for job in scheduler.get_jobs()}
        for job_id in jobs.keys() - schedules.keys():
            scheduler.remove_job(job_id)
        for schedule_id, schedule in schedules.items():
            try:
                self._sync_one(scheduler, schedule, jobs.get(schedule_id))
            except Exception:  # one broken schedule must not stop the others
                log.exception("schedule %s: not scheduled", schedule_id)

    @staticmethod
    def _sync_one(scheduler: BackgroundScheduler, schedule: ScheduleView, job: Job | None) -> None:
        """Add the schedule's job if missing; pause or resume it to match the schedule."""
        if job is None:
            # First due time counted from the schedule's creation, not from when a scheduler first saw
            # it: one created while no scheduler ran still gets its first run (misfire policy).
            trigger = trigger_for(schedule)
            created = datetime.fromtimestamp(schedule.created_at, UTC)
            job = scheduler.add_job(
                fire_placeholder,
                trigger,
                args=(schedule.id,),
                id=schedule.id,
                name=schedule.name,
                next_run_time=trigger.get_next_fire_time(None, created),
            )
        if schedule.paused and job.next_run_time is not None:
            scheduler.pause_job(schedule.id)
        elif not schedule.paused and job.next_run_time is None:
            scheduler.resume_job(schedule.id)

    def lead(self) -> None:
        """Run APScheduler while this process holds the lease."""
        scheduler = self._build_scheduler()
        scheduler.start(paused=True)  # load persisted jobs, sync, then process due times
        try:
            seen_version = -1
            renew_every_s = self.settings.regression_leader_ttl_s / 3.0
            next_renew = time.monotonic() + renew_every_s
            first = True
            while not self.stop_event.is_set():
                version = self.regression.schedules_version()
                if version != seen_version:
                    self.sync(scheduler)
                    seen_version = version
                if first:
                    scheduler.resume()
                    first = False
                if time.monotonic() >= next_renew:
                    if not self.renew():
                        log.warning("%s lost the scheduler lease; standing by", self.name)
                        return
                    next_renew = time.monotonic() + renew_every_s
                self.stop_event.wait(min(SYNC_INTERVAL_S, renew_every_s))
        finally:
            scheduler.shutdown(wait=True)

    def run(self) -> None:
        """Stand by and lead in turn until ``stop_event`` is set.

        Redis going away (the private one restarted by ``serve``, a failover) ends a term as leader, not
        the scheduler: it logs one line, stands by until Redis answers, and then leads again at once if its
        lease survived (an AOF restore keeps it: ``renew`` succeeds), or competes for it once it lapsed.
        """
        log.info("%s started", self.name)
        redis_down = False
        try:
            while not self.stop_event.is_set():
                try:
                    leading = self.renew() or self.try_acquire()
                    if redis_down:
                        log.info("%s: Redis answers again", self.name)
                        redis_down = False
                    if leading:
                        log.info("%s is the scheduler leader", self.name)
                        self.lead()
                except redis.RedisError as error:
                    if not redis_down:
                        log.warning("%s: Redis unavailable (%s); standing by", self.name, error)
                    redis_down = True
                self.stop_event.wait(min(1.0, self.settings.regression_leader_ttl_s / 3.0))
        finally:
            with contextlib.suppress(redis.RedisError):  # Redis gone: the lease lapses by its TTL
                self.release()
            self.client.close()


def _connect_args(settings: Settings) -> dict[str, Any]:
    """RedisJobStore's connection arguments (it builds its own client) from the Redis URL."""
    assert settings.redis_url is not None
    args = parse_url(settings.redis_url)
    args.pop("connection_class", None)
    return args


def start_scheduler_thread(settings: Settings) -> tuple[RegressionScheduler, threading.Thread]:
    """A scheduler in a daemon thread (``hgrender serve``); stop it with ``scheduler.stop_event.set()``."""
    scheduler = RegressionScheduler(settings)
    thread = threading.Thread(target=scheduler.run, name="regression-scheduler", daemon=True)
    thread.start()
    return scheduler, thread
