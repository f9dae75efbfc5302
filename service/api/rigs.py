"""``/api/v1/rigs``: what rigs exist and whether they are busy."""

from __future__ import annotations

from fastapi import APIRouter, Depends, HTTPException
from sqlalchemy import select
from sqlalchemy.orm import Session

from service.api import auth
from service.api.deps import SessionDep
from service.api.schemas import RigCreate, RigOut
from service.campaigns import rig_busy
from service.db.models import Rig
from service.engine.rigs import rig_config_errors

router = APIRouter(prefix="/api/v1/rigs", tags=["rigs"])


@router.get("", response_model=list[RigOut], dependencies=[Depends(auth.viewer)])
def list_rigs(session: SessionDep) -> list[RigOut]:
    rigs = session.scalars(select(Rig).order_by(Rig.name)).all()
    return [_rig_out(session, rig) for rig in rigs]


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
    problems = rig_config_errors(body.chamber, body.turntable, body.sensors)
    if problems:
        detail = [
            {"loc": ["body", *_loc(path)], "msg": why, "type": "value_error"}
            for path, why in problems
        ]
        raise HTTPException(status_code=422, detail=detail)
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


def _rig_out(session: Session, rig: Rig) -> RigOut:
    return RigOut(
        name=rig.name,
        chamber=rig.chamber or {},
        turntable=rig.turntable or {},
        sensors=rig.sensors or [],
        busy=rig_busy(session, rig.name),
    )
