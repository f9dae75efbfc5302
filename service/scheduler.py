"""Overnight schedules: fire due schedules into queued campaigns, exactly once across processes.

Each firing is one transaction that starts with a conditional UPDATE
(``WHERE id = ? AND next_run_at = <the value we read>``): whichever process
moves ``next_run_at`` first creates the campaign; the others match no row and
skip. A busy rig needs nothing special: the campaign simply waits in ``queued``.
Missed firings (service down over the night) collapse into one: the next cron
occurrence is computed from now, not from the missed time.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import logging
from collections.abc import Callable
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from croniter import croniter
from pydantic import ValidationError
from sqlalchemy import select, update
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from service.campaigns import create_campaign, mount_issues, plan_check
from service.db.models import Schedule
from service.db.timestamps import as_utc, utcnow
from service.engine.spec import CampaignCreate
from service.event_log import log_event

log = logging.getLogger(__name__)

Clock = Callable[[], dt.datetime]


def next_cron_run(cron: str, after: dt.datetime, timezone: str | None = None) -> dt.datetime:
    """The first occurrence of ``cron`` strictly after ``after``, as a UTC instant.

    ``cron`` reads in ``timezone`` (an IANA name, e.g. ``Europe/Berlin``; None = UTC),
    so "0 20 * * 1-5" stays 20:00 on the lab's wall clock across daylight-saving
    changes. A local time that a spring-forward skips fires at the first valid
    instant after it (croniter's rule).
    """
    start = as_utc(after)
    assert start is not None
    if timezone:
        start = start.astimezone(ZoneInfo(timezone))
    return croniter(cron, start).get_next(dt.datetime).astimezone(dt.UTC)


def timezone_is_valid(name: str) -> bool:
    try:
        ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        return False
    return True


def cron_is_valid(cron: str) -> bool:
    return croniter.is_valid(cron)


class Scheduler:
    """Polls the schedules table; ``now`` is injectable so tests control time."""

    def __init__(
        self,
        session_factory: sessionmaker[Session],
        *,
        now: Clock = utcnow,
        interval_s: float = 5.0,
    ) -> None:
        self._factory = session_factory
        self._now = now
        self._interval_s = interval_s
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self._loop(), name="soakcal-scheduler")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    async def _loop(self) -> None:
        while True:
            try:
                await asyncio.to_thread(self.run_due)
            except Exception:  # a bad tick (DB restart) must not kill the loop
                log.exception("scheduler tick failed; retrying in %.1f s", self._interval_s)
            await asyncio.sleep(self._interval_s)

    def run_due(self) -> list[int]:
        """Fire every due schedule once; returns the ids of the campaigns created here."""
        now = as_utc(self._now())
        assert now is not None
        with self._factory() as session:
            due = session.execute(
                select(Schedule.id, Schedule.next_run_at, Schedule.cron, Schedule.timezone)
                .where(Schedule.next_run_at.is_not(None), Schedule.next_run_at <= now)
                .order_by(Schedule.next_run_at)
            ).all()
        created: list[int] = []
        for schedule_id, seen_next_run_at, cron, timezone in due:
            following = next_cron_run(cron, now, timezone) if cron else None
            try:
                campaign_id = self._fire(schedule_id, seen_next_run_at, following, now)
            except OperationalError:  # SQLite lock contention: the next tick retries
                log.warning("schedule %s: database busy, will retry", schedule_id)
                continue
            if campaign_id is not None:
                created.append(campaign_id)
        return created

    def _fire(
        self,
        schedule_id: int,
        seen_next_run_at: dt.datetime,
        following: dt.datetime | None,
        now: dt.datetime,
    ) -> int | None:
        with self._factory() as session:
            # The claim is the transaction's first statement: on SQLite it takes the
            # write lock before this transaction has read anything that could be stale.
            claimed = session.execute(
                update(Schedule)
                .where(Schedule.id == schedule_id, Schedule.next_run_at == seen_next_run_at)
                .values(next_run_at=following, last_run_at=now)
                .execution_options(synchronize_session=False)
            ).rowcount
            if claimed != 1:
                session.rollback()
                return None
            schedule = session.get(Schedule, schedule_id)
            assert schedule is not None
            campaign_id = self._create(session, schedule)
            session.execute(
                update(Schedule)
                .where(Schedule.id == schedule_id)
                .values(last_campaign_id=campaign_id)
                .execution_options(synchronize_session=False)
            )
            session.commit()
            log_event("schedule fired", schedule=schedule_id, campaign=campaign_id)
            return campaign_id

    def _create(self, session: Session, schedule: Schedule) -> int | None:
        try:
            spec = CampaignCreate.model_validate(schedule.campaign)
        except ValidationError as exc:  # stored before a contract change: skip, don't loop
            log_event("schedule skipped", schedule=schedule.id,
                      error=f"stored campaign no longer valid: {exc.errors()[:1]}")
            return None
        check = plan_check(session, spec)
        issues = check.issues + mount_issues(session, spec)
        if issues:  # e.g. the rig was removed since: skip this firing, keep the schedule
            where = ".".join(str(p) for p in ("campaign", *issues[0].loc))
            log_event("schedule skipped", schedule=schedule.id,
                      error=f"campaign not valid any more: {where}: {issues[0].msg}")
            return None
        return create_campaign(session, spec, schedule_id=schedule.id, check=check).id
