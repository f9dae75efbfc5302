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
    responses={409: {"description": "a rig of that name exists"}},
)
def create_rig(body: RigCreate, session: SessionDep) -> RigOut:
    if session.scalar(select(Rig.id).where(Rig.name == body.name)) is not None:
        raise HTTPException(status_code=409, detail=f"rig {body.name!r} already exists")
    rig = Rig(**body.model_dump())
    session.add(rig)
    session.commit()
    return _rig_out(session, rig)


def _rig_out(session: Session, rig: Rig) -> RigOut:
    return RigOut(
        name=rig.name,
        chamber=rig.chamber or {},
        turntable=rig.turntable or {},
        sensors=rig.sensors or [],
        busy=rig_busy(session, rig.name),
    )
