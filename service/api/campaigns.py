"""``/api/v1/campaigns``: create, inspect, control, export and follow soak campaigns."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from fastapi.responses import PlainTextResponse, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from calibration.placement import HAND_HELD_TOL_DEG
from service.api import auth
from service.api.deps import DbIdPath, SessionDep
from service.api.recording_csv import render_probes_csv, render_recording_csv
from service.api.schemas import CampaignCreate, CampaignOut, CampaignState, Progress
from service.campaigns import (
    CampaignNotFound,
    apply_action,
    campaign_serials,
    create_campaign,
    mount_issues,
    plan_check,
    positions_count,
    stored_duration_s,
)
from service.db.models import Campaign, Measurement, Rig, SoakProbe
from service.db.timestamps import as_utc
from service.dry_run import PlanIssue
from service.engine.placement import hand_placed_references
from service.engine.states import PHASES, TERMINAL

router = APIRouter(prefix="/api/v1/campaigns", tags=["campaigns"])

_NOT_FOUND = {404: {"description": "no such campaign"}}
_CONFLICT = {409: {"description": "the action is illegal in the campaign's state"}}


@router.post("", response_model=CampaignOut, status_code=201, dependencies=[Depends(auth.operator)])
def create(body: CampaignCreate, session: SessionDep) -> CampaignOut:
    """Queue a campaign; it waits in ``queued`` while its rig is busy.

    The dry run (``service.dry_run``) refuses with 422 naming the field a campaign
    that could never produce a calibration (positions that cannot identify the model
    in the rig's mode, a setpoint outside the chamber's range, a ramp the chamber
    cannot follow); the 201 carries ``predicted_duration_s``.
    """
    check = plan_check(session, body)
    errors = issue_errors(check.issues + mount_issues(session, body), ("body",))
    if errors:
        raise HTTPException(status_code=422, detail=errors)
    campaign = create_campaign(session, body, check=check)
    session.commit()
    return campaign_out(session, campaign)


# Largest page of ``GET /campaigns?limit=``: a dashboard screen is a few dozen rows.
MAX_PAGE = 1000


class CampaignListQuery(BaseModel):
    """``GET /campaigns`` parameters; an unknown one (``?limt=10``) is a 422 naming it
    instead of a silently unfiltered list."""

    model_config = ConfigDict(extra="forbid")
    state: CampaignState | None = None
    limit: int | None = Field(
        default=None, ge=1, le=MAX_PAGE,
        description="at most this many campaigns, newest first (without it: every campaign)")
    offset: int = Field(default=0, ge=0, le=2**31 - 1,
                        description="skip this many newest campaigns first")


@router.get("", response_model=list[CampaignOut], dependencies=[Depends(auth.viewer)])
def list_campaigns(
    session: SessionDep, response: Response, query: Annotated[CampaignListQuery, Query()],
) -> list[CampaignOut]:
    """Campaigns, newest first. With ``limit``/``offset`` one page of them; the
    ``X-Total-Count`` header gives how many match, so a client knows when to stop."""
    rows = select(Campaign).order_by(Campaign.id.desc())
    count = select(func.count(Campaign.id))
    if query.state is not None:
        rows = rows.where(Campaign.state == query.state)
        count = count.where(Campaign.state == query.state)
    if query.limit is not None or query.offset:
        rows = rows.offset(query.offset).limit(query.limit)
    response.headers["X-Total-Count"] = str(session.scalar(count))
    return [campaign_out(session, c) for c in session.scalars(rows).all()]


@router.get(
    "/{campaign_id}",
    response_model=CampaignOut,
    responses=_NOT_FOUND,
    dependencies=[Depends(auth.viewer)],
)
def get_campaign(campaign_id: DbIdPath, session: SessionDep) -> CampaignOut:
    return campaign_out(session, _get_or_404(session, campaign_id))


def _control(action: str):  # type: ignore[no-untyped-def]
    def handler(campaign_id: DbIdPath, session: SessionDep) -> CampaignOut:
        try:
            return campaign_out(session, apply_action(session, campaign_id, action))
        except CampaignNotFound as exc:
            raise HTTPException(status_code=404, detail=str(exc)) from exc

    handler.__name__ = f"{action}_campaign"
    handler.__doc__ = {
        "pause": "Pause at the next safe point (a queued campaign pauses at once).",
        "resume": "Resume a paused campaign from its persisted cursor.",
        "abort": "Abort: the runner parks the chamber at a safe temperature, the table at rest.",
    }[action]
    return handler


for _action in ("pause", "resume", "abort"):
    router.add_api_route(
        f"/{{campaign_id}}/{_action}",
        _control(_action),
        methods=["POST"],
        response_model=CampaignOut,
        responses={**_NOT_FOUND, **_CONFLICT},
        dependencies=[Depends(auth.operator)],
    )


@router.get(
    "/{campaign_id}/recording.csv",
    response_class=PlainTextResponse,
    responses={**_NOT_FOUND, 200: {"content": {"text/csv": {}}, "description": "recording v1"}},
    dependencies=[Depends(auth.viewer)],
)
def recording_csv(
    campaign_id: DbIdPath, session: SessionDep,
    sensor: Annotated[str | None, Query(
        max_length=64, description="which sensor of a several-sensor campaign")] = None,
) -> PlainTextResponse:
    """The measurements so far, in recording format v1, time order (one sensor's).

    A several-sensor campaign needs ``sensor`` (422 naming the choices without it);
    a one-sensor campaign takes its own serial or nothing.
    """
    campaign = _get_or_404(session, campaign_id)
    serials = _sensor_choice(campaign_id, campaign, sensor)
    query = select(Measurement).where(Measurement.campaign_id == campaign_id)
    if len(serials) > 1:
        query = query.where(Measurement.sensor == sensor)
    rows = session.scalars(
        query.order_by(Measurement.t_s, Measurement.step, Measurement.position))
    name = f"campaign-{campaign_id}" + (f"-{sensor}" if len(serials) > 1 else "")
    rig = session.scalar(select(Rig).where(Rig.name == campaign.rig))
    hand_placed = rig is not None and hand_placed_references(rig.turntable)
    return PlainTextResponse(
        render_recording_csv(rows, HAND_HELD_TOL_DEG if hand_placed else None),
        media_type="text/csv; charset=utf-8",
        headers={"Content-Disposition": f'attachment; filename="{name}.csv"'},
    )


def _sensor_choice(campaign_id: int, campaign: Any, sensor: str | None) -> list[str]:
    """The campaign's serials; 422 naming the choices when ``sensor`` is missing (several
    sensors) or not one of them."""
    serials = campaign_serials(campaign.spec or {}, campaign.sensor)
    if sensor is None and len(serials) > 1:
        raise HTTPException(status_code=422, detail=[field_error(
            ("query", "sensor"), f"campaign {campaign_id} has {len(serials)} sensors: "
            f"choose one of {', '.join(serials)}", None)])
    if sensor is not None and sensor not in serials:
        raise HTTPException(status_code=422, detail=[field_error(
            ("query", "sensor"), f"campaign {campaign_id} has no sensor {sensor!r}: "
            f"choose one of {', '.join(serials)}", sensor)])
    return serials


@router.get(
    "/{campaign_id}/probes.csv",
    response_class=PlainTextResponse,
    responses={**_NOT_FOUND, 200: {"content": {"text/csv": {}},
                                   "description": "soak probes, recording-format rows"}},
    dependencies=[Depends(auth.viewer)],
)
def probes_csv(
    campaign_id: DbIdPath, session: SessionDep,
    sensor: Annotated[str | None, Query(
        max_length=64, description="which sensor of a several-sensor campaign")] = None,
) -> PlainTextResponse:
    """The soak probes so far (die-temperature probes taken while soaking), one sensor's,
    time order: t_s, step, setpoint_c, chamber_c, sensor_c, ref_x/y/z, ax/ay/az, n.

    The measurements the campaign's rate gain (``rate_gain: measured``) comes from.
    Sensor choice as for ``recording.csv``.
    """
    campaign = _get_or_404(session, campaign_id)
    serials = _sensor_choice(campaign_id, campaign, sensor)
    query = select(SoakProbe).where(SoakProbe.campaign_id == campaign_id)
    if len(serials) > 1:
        query = query.where(SoakProbe.sensor == sensor)
    rows = session.scalars(query.order_by(SoakProbe.t_s, SoakProbe.id))
    name = f"campaign-{campaign_id}-probes" + (f"-{sensor}" if len(serials) > 1 else "")
    return PlainTextResponse(
        render_probes_csv(rows), media_type="text/csv; charset=utf-8",
        headers={"Content-Disposition": f'attachment; filename="{name}.csv"'},
    )


@router.get(
    "/{campaign_id}/events",
    response_class=StreamingResponse,
    responses={
        **_NOT_FOUND,
        200: {
            "content": {"text/event-stream": {}},
            "description": "`event: progress` with the campaign JSON whenever it changes; "
            "`event: end` at a terminal state, then the stream closes",
        },
    },
    dependencies=[Depends(auth.viewer)],
)
async def campaign_events(campaign_id: DbIdPath, request: Request) -> StreamingResponse:
    """Server-sent progress events, read from the database (the runner may be elsewhere)."""
    factory = request.app.state.session_factory
    first = await run_in_threadpool(_load_view, factory, campaign_id)
    if first is None:
        raise HTTPException(status_code=404, detail=f"campaign {campaign_id} not found")
    settings = request.app.state.settings
    return StreamingResponse(
        _event_stream(
            factory, campaign_id, first, settings.events_poll_s, settings.events_heartbeat_s
        ),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


async def _event_stream(
    factory: sessionmaker[Session],
    campaign_id: int,
    view: CampaignOut,
    poll_s: float,
    heartbeat_s: float,
) -> AsyncIterator[str]:
    last_payload = None
    last_sent = time.monotonic()
    event_id = 0
    while True:
        payload = view.model_dump_json()
        if payload != last_payload:
            event_id += 1
            yield f"event: progress\nid: {event_id}\ndata: {payload}\n\n"
            last_payload, last_sent = payload, time.monotonic()
        if view.state in TERMINAL:
            yield f"event: end\nid: {event_id + 1}\ndata: {_end_data(view)}\n\n"
            return
        if time.monotonic() - last_sent >= heartbeat_s:
            yield ": keep-alive\n\n"  # a comment line: clients ignore it, proxies see traffic
            last_sent = time.monotonic()
        await asyncio.sleep(poll_s)
        reloaded = await run_in_threadpool(_load_view, factory, campaign_id)
        if reloaded is None:  # deleted under us: nothing more to follow
            return
        view = reloaded


def _end_data(view: CampaignOut) -> str:
    import json

    body: dict[str, Any] = {
        "id": view.id,
        "state": view.state,
        "error": view.error,
        "calibration_id": view.calibration_id,
    }
    return json.dumps(body)


def _load_view(factory: sessionmaker[Session], campaign_id: int) -> CampaignOut | None:
    with factory() as session:
        campaign = session.get(Campaign, campaign_id)
        return None if campaign is None else campaign_out(session, campaign)


def _get_or_404(session: Session, campaign_id: int) -> Campaign:
    campaign = session.get(Campaign, campaign_id)
    if campaign is None:
        raise HTTPException(status_code=404, detail=f"campaign {campaign_id} not found")
    return campaign


def campaign_out(session: Session, campaign: Campaign) -> CampaignOut:
    """The API view: contract fields, progress completed from the cursor and the spec, and
    the dry run's prediction as stored at creation (``service.campaigns.stored_prediction``)."""
    return CampaignOut(
        id=campaign.id,
        rig=campaign.rig,
        sensor=campaign.sensor,
        sensors=campaign_serials(campaign.spec or {}, campaign.sensor),
        state=campaign.state,  # type: ignore[arg-type]
        created_at=as_utc(campaign.created_at),  # type: ignore[arg-type]
        started_at=as_utc(campaign.started_at),
        finished_at=as_utc(campaign.finished_at),
        progress=progress_of(campaign),
        calibration_id=campaign.calibration_id,
        calibration_ids=dict(campaign.calibration_ids or {}) or (
            {} if campaign.calibration_id is None
            else {campaign.sensor: campaign.calibration_id}),
        sensors_dropped=dict(campaign.sensors_dropped or {}),
        error=campaign.error,
        requested_action=campaign.requested_action,
        suspended_reason=campaign.suspended_reason,
        spec=campaign.spec or {},
        schedule_id=campaign.schedule_id,
        predicted_duration_s=stored_duration_s(session, campaign),
    )


def progress_of(campaign: Campaign) -> Progress:
    """``campaign.progress`` as written by the runner, gaps filled from cursor and spec."""
    live = dict(campaign.progress or {})
    spec = campaign.spec or {}
    setpoints_c = list(spec.get("setpoints_c") or [])
    step = int(_first(live.get("step"), campaign.cursor_step, 0))
    phase = _first(live.get("phase"), campaign.cursor_phase, "ramp")
    if phase not in PHASES:
        phase = "ramp"
    default_fraction = 1.0 if campaign.state == "completed" else 0.0
    fraction = float(_first(live.get("fraction"), default_fraction))
    setpoint_c = live.get("setpoint_c")
    if setpoint_c is None and 0 <= step < len(setpoints_c):
        setpoint_c = setpoints_c[step]
    positions = live.get("positions")
    if positions is None and spec.get("positions"):
        positions = positions_count(str(spec["positions"]))
    eta_s, eta_wall_s = live.get("eta_s"), live.get("eta_wall_s")
    if campaign.state in TERMINAL:
        eta_s = eta_wall_s = 0.0 if campaign.state == "completed" else None
    return Progress(
        step=step,
        steps=int(_first(live.get("steps"), len(setpoints_c))),
        phase=phase,
        position=int(_first(live.get("position"), campaign.cursor_position, 0)),
        positions=positions,
        fraction=min(1.0, max(0.0, fraction)),
        chamber_c=live.get("chamber_c"),
        setpoint_c=setpoint_c,
        eta_s=eta_s,
        eta_wall_s=eta_wall_s,
    )


def _first(*values: Any) -> Any:
    return next((v for v in values if v is not None), None)


def field_error(loc: tuple[str | int, ...], msg: str, value: Any) -> dict[str, Any]:
    """One 422 ``detail`` entry; the input echoed at most as a short prefix."""
    from service.api.door import short

    return {"type": "value_error", "loc": list(loc), "msg": msg, "input": short(value)}


def issue_errors(issues: list[PlanIssue], loc: tuple[str | int, ...]) -> list[dict[str, Any]]:
    """Refusals of the dry run and the mounting check as 422 ``detail`` entries under ``loc``."""
    return [field_error(loc + issue.loc, issue.msg, issue.value) for issue in issues]
