"""The scheduler: due schedules become queued campaigns exactly once, across processes."""

from __future__ import annotations

import datetime as dt
import threading

import pytest
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from service.campaigns import seed_sim_rig
from service.db.models import Campaign, Schedule
from service.db.session import make_session_factory, session_scope
from service.scheduler import Scheduler

NOW = dt.datetime(2030, 1, 7, 20, 0, 30, tzinfo=dt.UTC)  # a Monday, 30 s after 20:00
SPEC = {"rig": "sim", "sensor": "SN-0001", "setpoints_c": [-10.0, 20.0]}


@pytest.fixture
def factories(clean_db_url: str):  # type: ignore[no-untyped-def]
    """Two independent session factories (own engines, own pools): two service processes."""
    pair = [make_session_factory(clean_db_url) for _ in range(2)]
    with session_scope(pair[0]) as session:
        seed_sim_rig(session)
    yield pair
    for factory in pair:
        factory.kw["bind"].dispose()


def _add_schedule(sf: sessionmaker[Session], **values) -> int:  # type: ignore[no-untyped-def]
    with session_scope(sf) as session:
        schedule = Schedule(campaign=SPEC, **values)
        session.add(schedule)
        session.flush()
        return schedule.id


def _campaigns(sf: sessionmaker[Session]) -> list[Campaign]:
    with sf() as session:
        return list(session.scalars(select(Campaign).order_by(Campaign.id)))


def test_two_processes_fire_a_due_schedule_once(factories) -> None:  # type: ignore[no-untyped-def]
    sid = _add_schedule(
        factories[0], cron="0 20 * * 1-5", next_run_at=NOW - dt.timedelta(seconds=30)
    )
    schedulers = [Scheduler(f, now=lambda: NOW) for f in factories]
    created: list[list[int]] = [[], []]
    barrier = threading.Barrier(2)

    def tick(i: int) -> None:
        barrier.wait()
        for _ in range(3):
            created[i].extend(schedulers[i].run_due())

    threads = [threading.Thread(target=tick, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(created[0] + created[1]) == [c.id for c in _campaigns(factories[0])]
    assert len(created[0] + created[1]) == 1
    campaign = _campaigns(factories[1])[0]
    assert campaign.state == "queued" and campaign.schedule_id == sid
    assert campaign.spec["setpoints_c"] == [-10.0, 20.0] and campaign.spec["soak_min"] == 60
    with factories[1]() as session:
        schedule = session.get(Schedule, sid)
        assert schedule.last_campaign_id == campaign.id
        next_run = schedule.next_run_at.replace(tzinfo=dt.UTC)
    assert next_run == dt.datetime(2030, 1, 8, 20, 0, tzinfo=dt.UTC)  # Tuesday 20:00


def test_one_shot_fires_once_and_future_schedules_wait(factories) -> None:  # type: ignore[no-untyped-def]
    once = _add_schedule(factories[0], at=NOW, next_run_at=NOW)
    _add_schedule(
        factories[0], at=NOW + dt.timedelta(hours=1), next_run_at=NOW + dt.timedelta(hours=1)
    )
    scheduler = Scheduler(factories[0], now=lambda: NOW)
    assert len(scheduler.run_due()) == 1
    assert scheduler.run_due() == []
    with factories[0]() as session:
        fired = session.get(Schedule, once)
        assert fired.next_run_at is None and fired.last_run_at is not None


def test_a_busy_rig_leaves_the_new_campaign_queued(factories) -> None:  # type: ignore[no-untyped-def]
    with session_scope(factories[0]) as session:
        session.add(
            Campaign(
                rig="sim", sensor="SN-X", spec=SPEC, state="running", progress={}, steps_log=[]
            )
        )
    _add_schedule(factories[0], at=NOW, next_run_at=NOW)
    [cid] = Scheduler(factories[0], now=lambda: NOW).run_due()
    with factories[0]() as session:
        assert session.get(Campaign, cid).state == "queued"
        assert session.scalar(select(func.count()).select_from(Campaign)) == 2


async def test_the_loop_runs_in_the_background(factories) -> None:  # type: ignore[no-untyped-def]
    import asyncio

    _add_schedule(factories[0], at=NOW, next_run_at=NOW)
    scheduler = Scheduler(factories[0], now=lambda: NOW, interval_s=0.01)
    await scheduler.start()
    for _ in range(200):
        if _campaigns(factories[0]):
            break
        await asyncio.sleep(0.01)
    await scheduler.stop()
    assert len(_campaigns(factories[0])) == 1


def test_an_invalid_stored_campaign_is_skipped_not_retried_forever(factories) -> None:  # type: ignore[no-untyped-def]
    with session_scope(factories[0]) as session:
        session.add(Schedule(campaign={"rig": "gone", "sensor": "S"}, at=NOW, next_run_at=NOW))
        session.add(Schedule(campaign={"sensor": "no rig"}, at=NOW, next_run_at=NOW))
    scheduler = Scheduler(factories[0], now=lambda: NOW)
    assert scheduler.run_due() == []
    with factories[0]() as session:
        schedules = session.scalars(select(Schedule)).all()
        assert [s.next_run_at for s in schedules] == [None, None]  # consumed, not retried
        assert all(s.last_campaign_id is None for s in schedules)
    assert _campaigns(factories[0]) == []


def test_cron_reads_in_the_labs_time_zone_across_daylight_saving() -> None:
    from service.scheduler import next_cron_run

    # 20:00 in Berlin is 19:00 UTC in winter and 18:00 UTC in summer.
    winter = next_cron_run("0 20 * * *", dt.datetime(2030, 3, 30, 12, tzinfo=dt.UTC),
                           "Europe/Berlin")
    summer = next_cron_run("0 20 * * *", dt.datetime(2030, 3, 31, 12, tzinfo=dt.UTC),
                           "Europe/Berlin")
    assert winter == dt.datetime(2030, 3, 30, 19, tzinfo=dt.UTC)
    assert summer == dt.datetime(2030, 3, 31, 18, tzinfo=dt.UTC)
    assert next_cron_run("0 20 * * *", dt.datetime(2030, 3, 31, 12, tzinfo=dt.UTC)) == (
        dt.datetime(2030, 3, 31, 20, tzinfo=dt.UTC))


def test_a_zoned_schedule_fires_and_rearms_in_its_zone(factories) -> None:  # type: ignore[no-untyped-def]
    now = dt.datetime(2030, 7, 1, 18, 0, 5, tzinfo=dt.UTC)  # 20:00:05 in Berlin (CEST)
    sid = _add_schedule(factories[0], cron="0 20 * * *", timezone="Europe/Berlin",
                        next_run_at=now - dt.timedelta(seconds=5))
    assert len(Scheduler(factories[0], now=lambda: now).run_due()) == 1
    with factories[0]() as session:
        rearmed = session.get(Schedule, sid).next_run_at
    assert rearmed.replace(tzinfo=dt.UTC) == dt.datetime(2030, 7, 2, 18, tzinfo=dt.UTC)
