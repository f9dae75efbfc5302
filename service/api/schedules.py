"""``/api/v1/schedules``: one-shot (``at``) or cron campaigns, fired by ``service.scheduler``."""

from __future__ import annotations

import datetime as dt
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Response
from sqlalchemy import select
from sqlalchemy.orm import Session

from service.api import auth
from service.api.campaigns import field_error, issue_errors
from service.api.deps import DbIdPath, SessionDep
from service.api.schemas import ScheduleCreate, ScheduleOut
from service.campaigns import mount_issues, plan_check, stored_duration_s
from service.db.models import Schedule
from service.db.timestamps import as_utc, utcnow
from service.scheduler import cron_is_valid, next_cron_run, timezone_is_valid

router = APIRouter(prefix="/api/v1/schedules", tags=["schedules"])


@router.post("", response_model=ScheduleOut, status_code=201, dependencies=[Depends(auth.operator)])
def create_schedule(body: ScheduleCreate, session: SessionDep) -> ScheduleOut:
    check = plan_check(session, body.campaign)
    errors: list[dict[str, Any]] = issue_errors(
        check.issues + mount_issues(session, body.campaign), ("body", "campaign"))
    now = utcnow()
    if body.at is not None and as_utc(body.at) <= now:  # type: ignore[operator]
        errors.append(field_error(
            ("body", "at"),
            f"'at' {body.at.isoformat()} is in the past (now {now.isoformat(timespec='seconds')}"
            "); a one-shot schedule must fire in the future",
            body.at.isoformat(),
        ))
    if body.cron is not None and not cron_is_valid(body.cron):
        errors.append(field_error(
            ("body", "cron"),
            f"invalid cron expression {body.cron!r} (five fields: min hour dom mon dow)",
            body.cron,
        ))
    if body.timezone is not None and not timezone_is_valid(body.timezone):
        errors.append(field_error(
            ("body", "timezone"),
            f"unknown time zone {body.timezone!r} (an IANA name, e.g. Europe/Berlin)",
            body.timezone,
        ))
    if errors:
        raise HTTPException(status_code=422, detail=errors)
    at = as_utc(body.at)
    schedule = Schedule(
        campaign=body.campaign.stored(),
        dry_run=None if check.prediction is None else dict(check.prediction),
        at=at,
        cron=body.cron,
        timezone=body.timezone,
        next_run_at=at if at is not None else next_cron_run(body.cron or "", now,
                                                            body.timezone),
    )
    session.add(schedule)
    session.commit()
    return _out(session, schedule)


@router.get("", response_model=list[ScheduleOut], dependencies=[Depends(auth.viewer)])
def list_schedules(session: SessionDep) -> list[ScheduleOut]:
    return [_out(session, s)
            for s in session.scalars(select(Schedule).order_by(Schedule.id)).all()]


@router.delete(
    "/{schedule_id}",
    status_code=204,
    response_class=Response,
    responses={404: {"description": "no such schedule"}},
    dependencies=[Depends(auth.operator)],
)
def delete_schedule(schedule_id: DbIdPath, session: SessionDep) -> Response:
    """Remove a schedule; campaigns it already created are not touched."""
    schedule = session.get(Schedule, schedule_id)
    if schedule is None:
        raise HTTPException(status_code=404, detail=f"schedule {schedule_id} not found")
    session.delete(schedule)
    session.commit()
    return Response(status_code=204)


def _out(session: Session, s: Schedule) -> ScheduleOut:
    return ScheduleOut(
        id=s.id,
        campaign=s.campaign,
        at=as_utc(s.at),
        cron=s.cron,
        timezone=s.timezone,
        next_run_at=as_utc(s.next_run_at),
        last_run_at=as_utc(s.last_run_at),
        last_campaign_id=s.last_campaign_id,
        created_at=as_utc(s.created_at) or dt.datetime.now(dt.UTC),
        predicted_duration_s=stored_duration_s(session, s),
    )
