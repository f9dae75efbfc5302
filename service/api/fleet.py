"""Lot statistics: each SFEM parameter's spread over the calibrated sensors of one model.

A sensor whose calibration lands far from the rest of its lot is more often a
bad mount, a mislabelled position or a damaged part than a real outlier; a lab
sees it here before shipping. For each sensor model (``sensors.model``, else
the model the sensor reported at the campaign), the latest calibration of
every sensor gives the 12 SFEM parameters of the seed paper's Eq. 1 and their
temperature coefficients (d/dT), both at one reference temperature from the
stored thermal polynomials (Eq. 8, ``polynomial.physical_coefficients``).
Centre: the median; spread: σ = 1.4826 · MAD (the median absolute deviation,
scaled to a normal σ), so one bad sensor does not hide itself by widening the
spread. A sensor more than :data:`FLAG_SIGMA` σ from its lot's median is flagged.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query
from pydantic import BaseModel, Field
from sqlalchemy import cast, func, select
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.orm import Session

from service.api import auth
from service.api.deps import DbIdPath, SessionDep
from service.db.models import Calibration, Sensor

FLAG_SIGMA = 4.0
MAD_TO_SIGMA = 1.4826  # σ of a normal distribution = 1.4826 × its MAD
MIN_LOT = 5  # fewer sensors: a median and MAD say too little to flag anyone
# Sensors per lot whose values are sent for the plot (every flagged one, and an even sample
# of the rest): 10,000 sensors × 24 values would be megabytes for dots that overlap anyway.
MAX_PLOTTED = 400
PARAMETERS = ("bx", "by", "bz", "sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz")

router = APIRouter(prefix="/api/v1/fleet", tags=["fleet"], dependencies=[Depends(auth.viewer)])


class Spread(BaseModel):
    name: str = Field(description="SFEM parameter (bx…mz), or 'd<name>/dT' for its tempco")
    unit: str
    n: int
    median: float
    sigma: float = Field(description="1.4826 × median absolute deviation")


class Flag(BaseModel):
    sensor: str
    calibration_id: int
    name: str
    value: float
    z: float = Field(description="(value − lot median) / lot sigma")


class Lot(BaseModel):
    model: str
    sensors: int
    left_out: list[str] = Field(description="sensors whose valid range misses reference_c")
    spreads: list[Spread]
    flags: list[Flag]
    values: dict[str, list[tuple[str, int, float]]] = Field(
        description="name → [sensor, calibration id, value] for the fleet page's plot: every "
        f"flagged sensor and an even sample of the rest, {MAX_PLOTTED} sensors at most")
    plotted: int = Field(description="sensors in values")
    note: str | None


class LotStatistics(BaseModel):
    reference_c: float
    flag_sigma: float
    lots: list[Lot]


@router.get("/lots", response_model=LotStatistics)
def lot_statistics(
    session: SessionDep,
    reference_c: Annotated[float, Query(ge=-100, le=200, allow_inf_nan=False,
                                        description="temperature the parameters are read at")
                           ] = 25.0,
) -> LotStatistics:
    """Per sensor model: every SFEM parameter's and tempco's median and σ over the latest
    calibration of each sensor, and the sensors outside 4 σ."""
    lots = [lot for lot, _ in _lots(session, reference_c)]
    return LotStatistics(reference_c=reference_c, flag_sigma=FLAG_SIGMA, lots=lots)


def _lots(session: Session, reference_c: float) -> list[tuple[Lot, set[int]]]:
    """Each lot and the calibration ids it was computed from."""
    latest = select(func.max(Calibration.id)).group_by(Calibration.sensor)
    doc: Any = Calibration.model
    source: Any = Calibration
    if session.get_bind().dialect.name == "postgresql":
        # A json column is text: every path below would parse the ~15 kB document again.
        # Parse each once, into jsonb, in a materialised CTE (not inlined into each path).
        parsed = (select(Calibration.id, Calibration.sensor,
                         cast(Calibration.model, JSONB).label("doc"))
                  .where(Calibration.id.in_(latest)).cte("parsed").prefix_with("MATERIALIZED"))
        doc, source = parsed.c.doc, parsed.c
    # Only the parts of each model document the statistics read, extracted by the database.
    query = (select(source.id, source.sensor, Sensor.model,
                    doc["provenance"]["sensor_identity"]["reported_model"],
                    doc["temperature"]["centre_c"], doc["temperature"]["valid_c"],
                    doc["polynomial"]["physical_coefficients"],
                    doc["polynomial"]["physical_units"])
             .outerjoin(Sensor, Sensor.serial == source.sensor)
             .order_by(source.sensor))
    if source is Calibration:
        query = query.where(Calibration.id.in_(latest))
    rows = session.execute(query).all()
    by_model: dict[str, list[tuple[str, int, dict[str, Any]]]] = {}
    for cal_id, serial, sensor_model, reported, centre_c, valid_c, coeffs, units in rows:
        model = sensor_model or reported or "unknown"
        part = {"temperature": {"centre_c": centre_c, "valid_c": valid_c},
                "polynomial": {"physical_coefficients": coeffs, "physical_units": units}}
        by_model.setdefault(model, []).append((serial, cal_id, part))
    return [_lot(model, members, reference_c) for model, members in sorted(by_model.items())]


class LotCheck(BaseModel):
    calibration_id: int
    model: str | None = Field(description="its lot (sensor model); null: not in any lot")
    sensors: int = Field(description="sensors in the lot at reference_c")
    flags: list[Flag] = Field(description="its parameters outside 4 σ of the lot")
    note: str | None = Field(description="why no verdict can be given, when none can")


@router.get("/calibrations/{calibration_id}", response_model=LotCheck,
            responses={404: {"description": "no such calibration"}})
def calibration_lot_check(
    calibration_id: DbIdPath, session: SessionDep,
    reference_c: Annotated[float, Query(ge=-100, le=200, allow_inf_nan=False)] = 25.0,
) -> LotCheck:
    """This calibration against its lot: its parameters outside 4 σ, or why no verdict."""
    if session.get(Calibration, calibration_id) is None:
        raise HTTPException(status_code=404, detail=f"calibration {calibration_id} not found")
    for lot, members in _lots(session, reference_c):
        if calibration_id in members:
            mine = [f for f in lot.flags if f.calibration_id == calibration_id]
            return LotCheck(calibration_id=calibration_id, model=lot.model,
                            sensors=lot.sensors, flags=mine, note=lot.note)
    return LotCheck(calibration_id=calibration_id, model=None, sensors=0, flags=[], note=(
        f"not compared: not its sensor's latest calibration, or {reference_c:g} °C is "
        "outside its valid range"))


def parameters_at(doc: dict[str, Any], t_c: float) -> dict[str, tuple[float, str]] | None:
    """``{name: (value, unit)}`` of the 12 parameters and their d/dT at ``t_c`` from the
    model document's physical polynomials; None when ``t_c`` is outside its valid range."""
    poly = doc.get("polynomial") or {}
    temp = doc.get("temperature") or {}
    coefficients = poly.get("physical_coefficients") or {}
    units = poly.get("physical_units") or {}
    valid = temp.get("valid_c") or [math.nan, math.nan]
    centre = temp.get("centre_c")
    if centre is None or not valid[0] <= t_c <= valid[1]:
        return None
    dt = t_c - float(centre)
    out: dict[str, tuple[float, str]] = {}
    for name in PARAMETERS:
        c = [float(v) for v in coefficients.get(name) or []]
        if not c:
            continue
        unit = (units.get(name) or ["", ""])
        out[name] = (sum(cj * dt**j for j, cj in enumerate(c)), unit[0])
        slope = sum(j * cj * dt ** (j - 1) for j, cj in enumerate(c) if j)
        out[f"d{name}/dT"] = (slope, unit[1] if len(unit) > 1 else f"{unit[0]}/degC")
    return out


def _lot(model: str, members: list[tuple[str, int, dict[str, Any]]], t_c: float
         ) -> tuple[Lot, set[int]]:
    values: dict[str, list[tuple[str, int, float]]] = {}
    units: dict[str, str] = {}
    left_out: list[str] = []
    for serial, cal_id, doc in members:
        params = parameters_at(doc or {}, t_c)
        if params is None:
            left_out.append(serial)
            continue
        for name, (value, unit) in params.items():
            if math.isfinite(value):
                values.setdefault(name, []).append((serial, cal_id, value))
                units[name] = unit
    spreads: list[Spread] = []
    flags: list[Flag] = []
    for name, points in values.items():
        x = np.array([p[2] for p in points])
        median = float(np.median(x))
        sigma = MAD_TO_SIGMA * float(np.median(np.abs(x - median)))
        spreads.append(Spread(name=name, unit=units[name], n=x.size, median=median, sigma=sigma))
        if x.size < MIN_LOT or sigma <= 0:
            continue
        for serial, cal_id, value in points:
            z = (value - median) / sigma
            if abs(z) > FLAG_SIGMA:
                flags.append(Flag(sensor=serial, calibration_id=cal_id, name=name, value=value,
                                  z=round(z, 1)))
    n = len(members) - len(left_out)
    note = None if n >= MIN_LOT else (
        f"{n} sensor(s) at {t_c:g} °C: at least {MIN_LOT} are needed to flag one")
    compared = {c for points in values.values() for _, c, _ in points}
    shown = _plotted(compared, {f.calibration_id for f in flags})
    values = {k: [p for p in points if p[1] in shown] for k, points in values.items()}
    return Lot(model=model, sensors=n, left_out=left_out, spreads=spreads, flags=flags,
               values=values, plotted=len(shown), note=note), compared


def _plotted(members: set[int], flagged: set[int]) -> set[int]:
    """Every flagged calibration and an even sample of the others, MAX_PLOTTED at most."""
    if len(members) <= MAX_PLOTTED:
        return members
    rest = sorted(members - flagged)
    room = max(0, MAX_PLOTTED - len(flagged))
    return set(flagged) | {rest[i * len(rest) // room] for i in range(room)}
