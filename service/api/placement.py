"""``/api/v1/campaigns/{id}/placement``: the hand-placement a manual rig waits for.

``GET`` shows the current request (docs/manual-fixtures.md) or ``null``;
``POST`` (operator) confirms that the sensor is placed as asked. The engine's
manual table then checks the placement with a short capture and either moves
on or re-issues the request with the reason.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException
from pydantic import BaseModel, Field

from service.api import auth
from service.api.deps import DbIdPath, SessionDep
from service.db.models import Campaign
from service.engine.placement import PlacementConflict, confirm_request, read_request

router = APIRouter(prefix="/api/v1/campaigns", tags=["placement"])


class PlacementConfirm(BaseModel):
    """The operator's confirmation; ``position`` must be the one asked when given."""

    position: int | None = Field(default=None, ge=0, description="schedule index placed")


def _campaign_or_404(session: SessionDep, campaign_id: int) -> Campaign:
    camp = session.get(Campaign, campaign_id)
    if camp is None:
        raise HTTPException(status_code=404, detail=f"campaign {campaign_id} not found")
    return camp


_NOT_FOUND = {404: {"description": "no such campaign"}}


@router.get("/{campaign_id}/placement", dependencies=[Depends(auth.viewer)],
            responses=_NOT_FOUND)
def get_placement(campaign_id: DbIdPath, session: SessionDep) -> dict[str, Any]:
    """The campaign's current placement request (``request`` null when none was made)."""
    camp = _campaign_or_404(session, campaign_id)
    return {"campaign_id": campaign_id, "campaign_state": camp.state,
            "request": read_request(session, campaign_id)}


@router.post("/{campaign_id}/placement", dependencies=[Depends(auth.operator)],
             responses={**_NOT_FOUND,
                        409: {"description": "nothing pending, or another position is asked"}})
def confirm_placement(campaign_id: DbIdPath, body: PlacementConfirm,
                      session: SessionDep) -> dict[str, Any]:
    """Confirm the pending placement (409 when none is pending or ``position`` differs)."""
    camp = _campaign_or_404(session, campaign_id)
    if camp.state != "running":
        raise HTTPException(status_code=409, detail=f"campaign {campaign_id} is {camp.state}")
    try:
        request = confirm_request(session, campaign_id, body.position)
    except PlacementConflict as exc:
        raise HTTPException(status_code=409, detail=str(exc)) from exc
    session.commit()
    return {"campaign_id": campaign_id, "campaign_state": camp.state, "request": request}
