"""A campaign's temperature history for the dashboard's chart, from what the database stores.

The chamber's and each sensor's die temperature are stored with every
measurement (one row per position) and every soak probe (the die-temperature
probes taken while soaking); the setpoint with both. Read together in time
order they are the campaign's thermal record: the chart a lab reads the next
morning is drawn from it, not from what one open page happened to see. Time
is the campaign's own clock ``t_s`` (seconds since it started, continuous
across restarts; on a sped-up sim rig, rig seconds).
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException
from pydantic import BaseModel, Field
from sqlalchemy import literal, select, union_all

from service.api import auth
from service.api.deps import DbIdPath, SessionDep
from service.campaigns import campaign_serials
from service.db.models import Campaign, Measurement, SoakProbe

# Points per series at most: a 640 px chart cannot show more, and a week-long campaign's
# probes would otherwise be a megabyte per re-read.
MAX_POINTS = 1500

router = APIRouter(prefix="/web/campaigns", tags=["dashboard"],
                   dependencies=[Depends(auth.viewer)])


class TemperatureHistory(BaseModel):
    campaign_id: int
    time: str = Field(description="what t_s counts: seconds since the campaign started")
    chamber_c: list[tuple[float, float]] = Field(description="[t_s, chamber air °C]")
    setpoint_c: list[tuple[float, float]] = Field(description="[t_s, setpoint °C]")
    die_c: dict[str, list[tuple[float, float]]] = Field(
        description="sensor serial → [t_s, die °C] (the sensor's own temperature reading)")
    soaks: list[dict[str, Any]] = Field(
        description="per finished soak: step, setpoint_c, soak_start_t_s, soak_end_t_s, reason")


@router.get("/{campaign_id}/temperatures", response_model=TemperatureHistory,
            responses={404: {"description": "no such campaign"}})
def temperature_history(campaign_id: DbIdPath, session: SessionDep) -> TemperatureHistory:
    """Chamber air, setpoint and each sensor's die temperature over the campaign so far."""
    campaign = session.get(Campaign, campaign_id)
    if campaign is None:
        raise HTTPException(status_code=404, detail=f"campaign {campaign_id} not found")
    serials = campaign_serials(campaign.spec or {}, campaign.sensor)
    first = serials[0]
    rows = session.execute(_history_query(campaign_id)).all()
    chamber: list[tuple[float, float]] = []
    setpoint: list[tuple[float, float]] = []
    die: dict[str, list[tuple[float, float]]] = {}
    for t_s, setpoint_c, chamber_c, sensor_c, sensor in rows:
        serial = sensor or first  # one-sensor campaigns store no serial per row
        if serial == first:  # the chamber is one: read it once, from the first sensor's rows
            if chamber_c is not None:
                chamber.append((t_s, chamber_c))
            setpoint.append((t_s, setpoint_c))
        if sensor_c is not None:
            die.setdefault(serial, []).append((t_s, sensor_c))
    soaks = [{k: s.get(k) for k in ("step", "setpoint_c", "soak_start_t_s", "soak_end_t_s",
                                    "reason")} for s in (campaign.steps_log or [])]
    return TemperatureHistory(
        campaign_id=campaign_id, time="seconds since the campaign started (rig clock)",
        chamber_c=thin(chamber), setpoint_c=thin(setpoint),
        # in the campaign's order of sensors (then any other serial the rows name)
        die_c={serial: thin(die[serial]) for serial in
               [*(s for s in serials if s in die), *(s for s in die if s not in serials)]},
        soaks=soaks)


def _history_query(campaign_id: int) -> Any:
    """Measurements and soak probes of the campaign as one time-ordered list."""
    columns = ("t_s", "setpoint_c", "chamber_c", "sensor_c", "sensor")
    measured = select(*(getattr(Measurement, c) for c in columns), literal(0).label("kind")
                      ).where(Measurement.campaign_id == campaign_id)
    probed = select(*(getattr(SoakProbe, c) for c in columns), literal(1).label("kind")
                    ).where(SoakProbe.campaign_id == campaign_id)
    both = union_all(measured, probed).subquery()
    return select(*(both.c[c] for c in columns)).order_by(both.c.t_s, both.c.kind)


def thin(points: list[tuple[float, float]], limit: int = MAX_POINTS) -> list[tuple[float, float]]:
    """At most ``limit`` points, evenly strided, the last one always kept (where it is now)."""
    if len(points) <= limit:
        return points
    stride = -(-len(points) // limit)
    kept = points[::stride]
    return kept if kept[-1] == points[-1] else [*kept, points[-1]]
