"""``/api/v1/rigs``: what rigs exist, whether they are busy; update, delete and check them."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Response
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from service.api import auth
from service.api.deps import SessionDep
from service.api.schemas import RigCreate, RigOut
from service.campaigns import busy_rig_names, rig_busy
from service.db.models import Campaign, Rig, RigLease
from service.engine.rigs import rig_config_errors

router = APIRouter(prefix="/api/v1/rigs", tags=["rigs"])


@router.get("", response_model=list[RigOut], dependencies=[Depends(auth.viewer)])
def list_rigs(session: SessionDep) -> list[RigOut]:
    rigs = session.scalars(select(Rig).order_by(Rig.name)).all()
    busy = busy_rig_names(session)
    return [_rig_out(session, rig, busy=rig.name in busy) for rig in rigs]


@router.post(
    "",
    response_model=RigOut,
    status_code=201,
    dependencies=[Depends(auth.admin)],
    responses={
        409: {"description": "a rig of that name exists"},
        422: {"description": "a driver config the drivers cannot use (the field is named)"},
    },
)
def create_rig(body: RigCreate, session: SessionDep) -> RigOut:
    """Register a rig. ``chamber.driver`` is ``sim`` or ``modbus`` (docs/api.md, rigs)."""
    _refuse_unusable(body.chamber, body.turntable, body.sensors)
    if session.scalar(select(Rig.id).where(Rig.name == body.name)) is not None:
        raise HTTPException(status_code=409, detail=f"rig {body.name!r} already exists")
    rig = Rig(**body.model_dump())
    session.add(rig)
    session.commit()
    return _rig_out(session, rig)


def _loc(path: str) -> list[str | int]:
    """``sensors[0].url`` → ``["sensors", 0, "url"]`` (FastAPI's loc style)."""
    out: list[str | int] = []
    for part in path.replace("]", "").replace("[", ".").split("."):
        out.append(int(part) if part.isdigit() else part)
    return out


def _rig_out(session: Session, rig: Rig, busy: bool | None = None) -> RigOut:
    return RigOut(
        name=rig.name,
        chamber=rig.chamber or {},
        turntable=rig.turntable or {},
        sensors=rig.sensors or [],
        busy=rig_busy(session, rig.name) if busy is None else busy,
    )


class RigUpdate(BaseModel):
    """PUT body: the whole driver config (the name is the path's)."""

    model_config = ConfigDict(extra="forbid")
    chamber: dict[str, Any]
    turntable: dict[str, Any] = Field(default_factory=dict)
    sensors: list[Any] = Field(default_factory=list)


class RigPatch(BaseModel):
    """PATCH body: the sections given replace the stored ones; the others stay."""

    model_config = ConfigDict(extra="forbid")
    chamber: dict[str, Any] | None = None
    turntable: dict[str, Any] | None = None
    sensors: list[Any] | None = None


class RigCheckRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    move: bool = Field(False, description="nudge the setpoint 0.5 °C and move the table 5°, "
                       "each then put back")


class RigCheckOut(BaseModel):
    rig: str
    passed: bool
    checks: list[dict[str, Any]]


_RIG_RESPONSES: dict[int | str, dict[str, Any]] = {
    404: {"description": "no such rig"},
    409: {"description": "a campaign uses the rig"},
    422: {"description": "a driver config the drivers cannot use (the field is named)"},
}


@router.put("/{name}", response_model=RigOut, dependencies=[Depends(auth.admin)],
            responses=_RIG_RESPONSES)
def replace_rig(name: str, body: RigUpdate, session: SessionDep) -> RigOut:
    """Replace a rig's driver config; refused (409) while a campaign is queued or runs on it."""
    return _update(session, name, body.chamber, body.turntable, body.sensors)


@router.patch("/{name}", response_model=RigOut, dependencies=[Depends(auth.admin)],
              responses=_RIG_RESPONSES)
def patch_rig(name: str, body: RigPatch, session: SessionDep) -> RigOut:
    """Replace the sections given (``chamber``, ``turntable``, ``sensors``); keep the rest."""
    rig = _get(session, name)
    return _update(session, name,
                   rig.chamber if body.chamber is None else body.chamber,
                   rig.turntable if body.turntable is None else body.turntable,
                   rig.sensors if body.sensors is None else body.sensors)


@router.delete("/{name}", status_code=204, dependencies=[Depends(auth.admin)],
               responses=_RIG_RESPONSES)
def delete_rig(name: str, session: SessionDep) -> Response:
    """Delete a rig; 409 while any campaign uses it or refers to it (see docs/api.md)."""
    rig = _get(session, name)
    _refuse_in_use(session, name)
    finished = session.scalar(select(func.count(Campaign.id)).where(Campaign.rig == name)) or 0
    if finished:
        # Campaign records (and their calibrations) name the rig: deleting it would orphan them.
        raise HTTPException(status_code=409, detail=(
            f"rig {name!r} is named by {finished} finished campaign(s); their records keep it"))
    lease = session.get(RigLease, name)
    if lease is not None:  # an expired lease (a live one made the rig busy above)
        session.delete(lease)
    session.delete(rig)
    session.commit()
    return Response(status_code=204)


@router.post("/{name}/check", response_model=RigCheckOut, dependencies=[Depends(auth.operator)],
             responses={404: {"description": "no such rig"},
                        409: {"description": "a campaign uses the rig's devices now"}})
def check_rig_endpoint(name: str, session: SessionDep,
                       body: RigCheckRequest | None = None) -> RigCheckOut:
    """The checks of ``soakcal rig check`` (docs/rig-check.md); 200 whether they pass or not."""
    from service.rig_check import check_rig, report

    rig = _get(session, name)
    if rig_busy(session, name):
        raise HTTPException(status_code=409, detail=f"rig {name!r} runs a campaign now")
    config = {"name": rig.name, "chamber": rig.chamber or {}, "turntable": rig.turntable or {},
              "sensors": rig.sensors or []}
    session.rollback()  # give the connection back: a check with --move takes seconds
    # A worker thread of its own event loop: the drivers are async, this handler is not.
    checks = asyncio.run(check_rig(config, move=bool(body and body.move)))
    return RigCheckOut(**report(name, checks))


def _get(session: Session, name: str) -> Rig:
    rig = session.scalar(select(Rig).where(Rig.name == name))
    if rig is None:
        raise HTTPException(status_code=404, detail=f"no rig {name!r}")
    return rig


def _refuse_in_use(session: Session, name: str) -> None:
    # A campaign paused while still queued does not hold the rig (rig_busy) but will use it.
    queued = session.scalar(select(Campaign.id).where(
        Campaign.rig == name, Campaign.state.in_(("queued", "paused"))))
    if rig_busy(session, name) or queued is not None:
        raise HTTPException(status_code=409,
                            detail=f"rig {name!r} is used by a queued, running or paused campaign")


def _refuse_unusable(chamber: dict[str, Any], turntable: dict[str, Any],
                     sensors: list[Any]) -> None:
    problems = rig_config_errors(chamber, turntable, sensors)
    if problems:
        detail = [
            {"loc": ["body", *_loc(path)], "msg": why, "type": "value_error"}
            for path, why in problems
        ]
        raise HTTPException(status_code=422, detail=detail)


def _update(session: Session, name: str, chamber: dict[str, Any], turntable: dict[str, Any],
            sensors: list[Any]) -> RigOut:
    rig = _get(session, name)
    _refuse_unusable(chamber, turntable, sensors)
    _refuse_in_use(session, name)
    rig.chamber, rig.turntable, rig.sensors = dict(chamber), dict(turntable), list(sensors)
    session.commit()
    return _rig_out(session, rig)
