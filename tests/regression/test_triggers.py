"""Due times of schedules: cron expressions in the schedule's time zone (DST included) and interval schedules
anchored at their creation time, identical in every scheduler process."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
from pydantic import ValidationError

from hgcore.regression.models import ScheduleCreate, ScheduleView, Suite, SuiteScene
from service.regression.scheduler import trigger_for

SUITE = Suite(scenes=[SuiteScene(example="cornell_box")])


def view(created_at: datetime, **fields: object) -> ScheduleView:
    request = ScheduleCreate(name="s", suite=SUITE, **fields)  # type: ignore[arg-type]
    return ScheduleView(**request.model_dump(), id="0" * 32, owner="ci", created_at=created_at.timestamp())


def fire_times(schedule: ScheduleView, after: datetime, count: int) -> list[datetime]:
    trigger, times, previous = trigger_for(schedule), [], None
    now = after
    for _ in range(count):
        previous = trigger.get_next_fire_time(previous, now)
        assert previous is not None
        times.append(previous.astimezone(UTC))
        now = previous
    return times


def test_cron_runs_in_the_schedules_time_zone_across_daylight_saving() -> None:
    # 02:30 Berlin time is 01:30 UTC in winter (CET, UTC+1) and 00:30 UTC in summer (CEST, UTC+2).
    schedule = view(datetime(2026, 3, 27, tzinfo=UTC), cron="30 2 * * *", timezone="Europe/Berlin")
    times = fire_times(schedule, datetime(2026, 3, 27, 12, tzinfo=UTC), 3)
    assert times[0] == datetime(2026, 3, 28, 1, 30, tzinfo=UTC)
    # 29 March 2026: clocks jump 02:00 → 03:00, so 02:30 does not exist that day; APScheduler runs it at
    # 03:30 CEST (01:30 UTC) — once — and 02:30 CEST (00:30 UTC) from the next day on.
    assert times[1] == datetime(2026, 3, 29, 1, 30, tzinfo=UTC)
    assert times[2] == datetime(2026, 3, 30, 0, 30, tzinfo=UTC)


def test_interval_due_times_are_anchored_at_creation() -> None:
    created = datetime(2026, 11, 22, 0, 0, 0, 250000, tzinfo=UTC)
    schedule = view(created, interval_s=60)
    times = fire_times(schedule, datetime(2026, 11, 22, 0, 5, 10, tzinfo=UTC), 2)
    # created + k·60 s: k = 6 is the first after 00:05:10 — whenever a scheduler happens to look.
    assert times == [
        datetime(2026, 11, 22, 0, 6, 0, 250000, tzinfo=UTC),
        datetime(2026, 11, 22, 0, 7, 0, 250000, tzinfo=UTC),
    ]


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"cron": "*/5 * * *"}, "cron: "),
        ({"cron": "0 0 * * * *"}, "cron: "),
        ({"cron": "61 * * * *"}, "cron: "),
        ({"interval_s": 0}, "interval_s"),
        ({}, "cron: give exactly one"),
        ({"cron": "0 2 * * *", "timezone": "Nowhere/Town"}, "timezone: "),
    ],
)
def test_invalid_timetables_name_the_field(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        ScheduleCreate(name="s", suite=SUITE, **fields)  # type: ignore[arg-type]
