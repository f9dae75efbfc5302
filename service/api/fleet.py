"""Lot statistics: each SFEM parameter's spread over the calibrated sensors of one model.

A sensor whose calibration lands far from the rest of its lot is more often a
bad mount, a mislabelled position or a damaged part than a real outlier; a lab
sees it here before shipping. For each sensor model (``sensors.model``, else
the model the sensor reported at the campaign), the latest calibration of
every sensor gives the 12 SFEM parameters of the seed paper's Eq. 1 and their
temperature coefficients (d/dT), both at one reference temperature from the
stored thermal polynomials (Eq. 8, ``polynomial.physical_coefficients``, copied to
the ``calibration_parameters`` table when the calibration is stored:
service/db/calibration_parameters.py), evaluated by the database.
Centre: the median; spread: σ = 1.4826 · MAD (the median absolute deviation,
scaled to a normal σ), so one bad sensor does not hide itself by widening the
spread. A sensor more than :data:`FLAG_SIGMA` σ from its lot's median is flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query
from pydantic import BaseModel, Field
from sqlalchemy import (
    Float,
    Integer,
    String,
    and_,
    case,
    func,
    literal_column,
    null,
    or_,
    select,
    text,
    union_all,
)
from sqlalchemy.orm import Session

from service.api import auth
from service.api.deps import DbIdPath, SessionDep
from service.db.calibration_parameters import PARAMETERS, slope_at, value_at
from service.db.models import Calibration, CalibrationParameter, Sensor

FLAG_SIGMA = 4.0
MAD_TO_SIGMA = 1.4826  # σ of a normal distribution = 1.4826 × its MAD
MIN_LOT = 5  # fewer sensors: a median and MAD say too little to flag anyone
# Sensors per lot whose values are sent for the plot (every flagged one, and an even sample
# of the rest): 10,000 sensors × 24 values would be megabytes for dots that overlap anyway.
MAX_PLOTTED = 400

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
    """Each lot and the calibration ids it was computed from.

    The values come from ``calibration_parameters`` (one row per calibration and SFEM
    parameter, written when the calibration is stored), evaluated at ``reference_c`` by
    the database. PostgreSQL also computes the medians and MADs (``percentile_cont``) and
    picks the flagged values, so only the plotted sample travels; SQLite has no
    percentile, so there numpy computes the same from the same rows.
    """
    members = _members(session, reference_c)
    if session.get_bind().dialect.name == "postgresql":
        spreads, flags = _spreads_in_sql(session, reference_c)
        shown = _plotted_by_lot(members, flags)
        values, _ = _values(session, reference_c, shown)
    else:
        values, units = _values(session, reference_c, None)
        spreads, flags = _spreads_in_python(values, units)
        shown = _plotted_by_lot(members, flags)
    by_lot: dict[str, list[_Member]] = {}
    for m in members:
        by_lot.setdefault(m.lot, []).append(m)
    out = []
    for model, lot_members in sorted(by_lot.items()):
        compared = {m.calibration_id for m in lot_members if m.in_range}
        n = len(compared)
        note = None if n >= MIN_LOT else (
            f"{n} sensor(s) at {reference_c:g} °C: at least {MIN_LOT} are needed to flag one")
        lot_shown = shown.get(model, set())
        lot_values = {name: [p for p in points if p[1] in lot_shown]
                      for name, points in values.get(model, {}).items()}
        out.append((Lot(model=model, sensors=n,
                        left_out=[m.sensor for m in lot_members if not m.in_range],
                        spreads=spreads.get(model, []), flags=flags.get(model, []),
                        values=lot_values, plotted=len(lot_shown), note=note), compared))
    return out


def _plotted_by_lot(members: list[_Member], flags: Flags) -> dict[str, set[int]]:
    """lot → the calibration ids its plot shows (:func:`_plotted`)."""
    compared: dict[str, set[int]] = {}
    for m in members:
        if m.in_range:
            compared.setdefault(m.lot, set()).add(m.calibration_id)
    return {lot: _plotted(ids, {f.calibration_id for f in flags.get(lot, [])})
            for lot, ids in compared.items()}


@dataclass(frozen=True)
class _Member:
    calibration_id: int
    sensor: str
    lot: str
    in_range: bool  # reference_c inside the calibration's valid range


def _lot_of() -> Any:
    """A sensor's lot: its registered model, else the model it reported, else 'unknown'."""
    # literals, not bound parameters: the expression is grouped by and must read the same
    empty = literal_column("''")
    return func.coalesce(func.nullif(Sensor.model, empty),
                         func.nullif(CalibrationParameter.reported_model, empty),
                         literal_column("'unknown'"))


def _latest() -> Any:
    """Each sensor's latest calibration id, as a subquery to join (a join, not ``IN``: the
    planner then knows it has one row per sensor and hashes instead of 10,000 lookups)."""
    return (select(func.max(Calibration.id).label("id")).group_by(Calibration.sensor)
            .subquery("latest"))


def _members(session: Session, t_c: float) -> list[_Member]:
    """The latest calibration of every sensor that has stored parameters, by sensor."""
    cp = CalibrationParameter
    latest = _latest()
    in_range = and_(cp.centre_c.is_not(None), cp.valid_lo_c <= t_c, cp.valid_hi_c >= t_c)
    # Grouped by the integer id alone: sensor and lot are the same on all its 12 rows.
    rows = session.execute(
        select(cp.calibration_id, func.max(cp.sensor), func.max(_lot_of()),
               func.max(case((in_range, 1), else_=0)))
        .join(latest, latest.c.id == cp.calibration_id)
        .outerjoin(Sensor, Sensor.serial == cp.sensor)
        .group_by(cp.calibration_id)).all()
    return sorted((_Member(int(c), s, lot, bool(r)) for c, s, lot, r in rows),
                  key=lambda m: m.sensor)


def _value_rows(t_c: float) -> Any:
    """Every compared (calibration, parameter)'s value and tempco at ``t_c``: a select."""
    cp = CalibrationParameter
    latest = _latest()
    return (select(cp.calibration_id, cp.sensor, _lot_of().label("lot"), cp.name,
                   value_at(t_c).label("x"), slope_at(t_c).label("dx"),
                   cp.unit, cp.tempco_unit)
            .join(latest, latest.c.id == cp.calibration_id)
            .outerjoin(Sensor, Sensor.serial == cp.sensor)
            .where(cp.centre_c.is_not(None), cp.valid_lo_c <= t_c, cp.valid_hi_c >= t_c))


Values = dict[str, dict[str, list[tuple[str, int, float]]]]  # lot → name → points


def _values(session: Session, t_c: float, ids: dict[str, set[int]] | None
            ) -> tuple[Values, dict[str, str]]:
    """lot → name → [(sensor, calibration id, value)] by sensor, names in :data:`PARAMETERS`
    order (each followed by its tempco), and each name's unit; only ``ids`` when given."""
    query = _value_rows(t_c)
    if ids is not None:
        wanted = sorted(set().union(*ids.values()))
        query = query.where(CalibrationParameter.calibration_id.in_(wanted))
    rows = session.execute(query).all()
    out: Values = {}
    units: dict[str, str] = {}
    for cal_id, serial, lot, name, x, dx, unit, tempco_unit in sorted(
            rows, key=lambda r: (r.lot, r.sensor)):
        for key, value, key_unit in ((name, x, unit), (f"d{name}/dT", dx, tempco_unit)):
            if value is not None and math.isfinite(value):
                out.setdefault(lot, {}).setdefault(key, []).append((serial, cal_id, float(value)))
                units[key] = key_unit
    return ({lot: dict(sorted(named.items(), key=lambda kv: name_order(kv[0])))
             for lot, named in out.items()}, units)


def name_order(name: str) -> int:
    """bx, dbx/dT, by, dby/dT, …: the order spreads, flags and plots list the names in."""
    if name.startswith("d") and name.endswith("/dT"):
        return 2 * PARAMETERS.index(name[1:-3]) + 1
    return 2 * PARAMETERS.index(name)


Spreads = dict[str, list[Spread]]
Flags = dict[str, list[Flag]]


def _flag(serial: str, cal_id: int, name: str, value: float, spread: Spread) -> Flag | None:
    """The flag of one value against its lot's spread (None: within 4 σ or no verdict)."""
    if spread.n < MIN_LOT or spread.sigma <= 0:
        return None
    z = (value - spread.median) / spread.sigma
    if abs(z) <= FLAG_SIGMA:
        return None
    return Flag(sensor=serial, calibration_id=cal_id, name=name, value=value, z=round(z, 1))


def _spreads_in_python(values: Values, units: dict[str, str]) -> tuple[Spreads, Flags]:
    """Median and σ = 1.4826 · MAD of every lot's parameter with numpy; the flags."""
    spreads: Spreads = {}
    flags: Flags = {}
    for lot, named in values.items():
        for name, points in named.items():
            x = np.array([p[2] for p in points])
            median = float(np.median(x))
            sigma = MAD_TO_SIGMA * float(np.median(np.abs(x - median)))
            spread = Spread(name=name, unit=units[name], n=x.size, median=median, sigma=sigma)
            spreads.setdefault(lot, []).append(spread)
            for serial, cal_id, value in points:
                flag = _flag(serial, cal_id, name, value, spread)
                if flag is not None:
                    flags.setdefault(lot, []).append(flag)
    return spreads, flags


def _spreads_in_sql(session: Session, t_c: float) -> tuple[Spreads, Flags]:
    """The same as :func:`_spreads_in_python`, computed by PostgreSQL in one statement.

    Per lot and parameter, the medians of the value and of its tempco
    (``percentile_cont(0.5)``), then the medians of ``|x − median|`` (the MADs); the
    statement returns those rows and, after them, the rows with a value or tempco
    beyond 4 σ of its lot, which :func:`_flag` turns into flags.
    """
    # The sorts of 10,000-sensor lots fit in memory with room to spare; the default 4 MB
    # spills them to disk (twice as slow). For this transaction only.
    session.execute(text("SET LOCAL work_mem = '64MB'"))
    rows = _value_rows(t_c).cte("cp_rows").prefix_with("MATERIALIZED")
    median = func.percentile_cont(0.5).within_group
    centre = (select(rows.c.lot, rows.c.name, func.count().label("n"),
                     func.max(rows.c.unit).label("unit"),
                     func.max(rows.c.tempco_unit).label("tempco_unit"),
                     median(rows.c.x).label("x_median"), median(rows.c.dx).label("dx_median"))
              .group_by(rows.c.lot, rows.c.name).cte("centre"))
    same_lot = and_(rows.c.lot == centre.c.lot, rows.c.name == centre.c.name)
    stats = (select(centre.c.lot, centre.c.name, centre.c.n, centre.c.unit,
                    centre.c.tempco_unit, centre.c.x_median, centre.c.dx_median,
                    median(func.abs(rows.c.x - centre.c.x_median)).label("x_mad"),
                    median(func.abs(rows.c.dx - centre.c.dx_median)).label("dx_mad"))
             .join(rows, same_lot)
             .group_by(*centre.c).cte("stats"))
    limit = FLAG_SIGMA * MAD_TO_SIGMA
    beyond = and_(stats.c.n >= MIN_LOT, or_(
        and_(stats.c.x_mad > 0, func.abs(rows.c.x - stats.c.x_median) > limit * stats.c.x_mad),
        and_(stats.c.dx_mad > 0,
             func.abs(rows.c.dx - stats.c.dx_median) > limit * stats.c.dx_mad)))
    null_float = null().cast(Float)
    statement = union_all(
        select(stats.c.lot, stats.c.name, stats.c.n, stats.c.unit, stats.c.tempco_unit,
               stats.c.x_median, stats.c.dx_median, stats.c.x_mad, stats.c.dx_mad,
               null().cast(Integer).label("calibration_id"), null().cast(String).label("sensor"),
               null_float.label("x"), null_float.label("dx")),
        select(rows.c.lot, rows.c.name, null().cast(Integer), null().cast(String),
               null().cast(String), null_float, null_float, null_float, null_float,
               rows.c.calibration_id, rows.c.sensor, rows.c.x, rows.c.dx)
        .join(stats, and_(rows.c.lot == stats.c.lot, rows.c.name == stats.c.name))
        .where(beyond))
    result = session.execute(statement).all()
    spreads: Spreads = {}
    by_key: dict[tuple[str, str], Spread] = {}
    for r in (r for r in result if r.calibration_id is None):
        for key, unit, mid, mad in ((r.name, r.unit, r.x_median, r.x_mad),
                                    (f"d{r.name}/dT", r.tempco_unit, r.dx_median, r.dx_mad)):
            by_key[(r.lot, key)] = Spread(name=key, unit=unit, n=r.n, median=mid,
                                          sigma=MAD_TO_SIGMA * mad)
    for (lot, _), spread in sorted(by_key.items(),
                                   key=lambda kv: (kv[0][0], name_order(kv[0][1]))):
        spreads.setdefault(lot, []).append(spread)
    candidates = []
    for r in (r for r in result if r.calibration_id is not None):
        for key, value in ((r.name, r.x), (f"d{r.name}/dT", r.dx)):
            flag = _flag(r.sensor, r.calibration_id, key, value, by_key[(r.lot, key)])
            if flag is not None:  # the one rule, also for the tempco of a flagged value
                candidates.append((r.lot, flag))
    flags: Flags = {}
    for lot, flag in sorted(candidates, key=lambda lf: (lf[0], name_order(lf[1].name),
                                                        lf[1].sensor)):
        flags.setdefault(lot, []).append(flag)
    return spreads, flags


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


def _plotted(members: set[int], flagged: set[int]) -> set[int]:
    """Every flagged calibration and an even sample of the others, MAX_PLOTTED at most."""
    if len(members) <= MAX_PLOTTED:
        return members
    rest = sorted(members - flagged)
    room = max(0, MAX_PLOTTED - len(flagged))
    return set(flagged) | {rest[i * len(rest) // room] for i in range(room)}
