"""Each stored calibration's 12 SFEM parameter polynomials, as rows of ``calibration_parameters``.

Lot statistics compare every sensor's parameters (the seed paper's Eq. 1) and their
temperature coefficients at one reference temperature. Reading them from each
calibration's model document means parsing ~15 kB of JSON per sensor on every request;
this module copies the physical polynomials (Eq. 8, ``polynomial.physical_coefficients``
about ``temperature.centre_c``) into their own table once, when the calibration is stored
(an ORM ``after_insert``/``after_update`` listener, so every writer is covered), and for
rows written without the ORM (the migration's backfill, bulk ``COPY``) by :func:`backfill`.

:func:`value_at` and :func:`slope_at` build the one expression that evaluates them at a
reference temperature, in SQL, on SQLite and PostgreSQL alike.
"""

from __future__ import annotations

import math
from typing import Any

from sqlalchemy import Connection, delete, event, func, insert, inspect, select
from sqlalchemy.sql.elements import ColumnElement

from service.db.models import Calibration, CalibrationParameter

PARAMETERS = ("bx", "by", "bz", "sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz")
MAX_DEGREE = 10  # the model file reader's limit (calibration/model_file.py); columns c0…c10
BACKFILL_BATCH = 500


def parameter_rows(calibration_id: int, sensor: str, doc: dict[str, Any] | None
                   ) -> list[dict[str, Any]]:
    """The ``calibration_parameters`` rows of one model document (none without polynomials).

    A parameter whose polynomial is empty, longer than :data:`MAX_DEGREE` + 1 or not finite
    gets no row: there is no number of it to compare.
    """
    # Storing a calibration must never fail here: a document of another shape (hand-made,
    # older) gets the rows that can be read from it, or none, and is then not compared.
    doc = doc if isinstance(doc, dict) else {}
    poly = _mapping(doc.get("polynomial"))
    temp = _mapping(doc.get("temperature"))
    coefficients = _mapping(poly.get("physical_coefficients"))
    units = _mapping(poly.get("physical_units"))
    valid = temp.get("valid_c")
    lo_c, hi_c = (_number(valid[0]), _number(valid[1])) if (
        isinstance(valid, list | tuple) and len(valid) == 2) else (None, None)
    reported = _mapping(_mapping(doc.get("provenance")).get("sensor_identity")).get(
        "reported_model")
    rows = []
    for name in PARAMETERS:
        raw = coefficients.get(name)
        c = [_number(v) for v in raw] if isinstance(raw, list) else []
        if not c or len(c) > MAX_DEGREE + 1 or any(v is None for v in c):
            continue
        unit = [str(u) for u in units.get(name) or ["", ""]] if isinstance(
            units.get(name), list | tuple) else ["", ""]
        row: dict[str, Any] = {
            "calibration_id": calibration_id, "name": name, "sensor": sensor,
            "reported_model": None if reported is None else str(reported)[:64],
            "centre_c": _number(temp.get("centre_c")), "valid_lo_c": lo_c, "valid_hi_c": hi_c,
            "unit": unit[0][:32] if unit else "",
            "tempco_unit": (unit[1] if len(unit) > 1 else f"{unit[0] if unit else ''}/degC")[:32],
        }
        row.update({f"c{j}": c[j] if j < len(c) else None for j in range(MAX_DEGREE + 1)})
        rows.append(row)
    return rows


def _mapping(x: Any) -> dict[str, Any]:
    return x if isinstance(x, dict) else {}


def _number(x: Any) -> float | None:
    """A finite float, or None (a string, a bool, NaN, infinity: not a coefficient)."""
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        return None
    return float(x)


def value_at(t_c: float) -> ColumnElement[float]:
    """``p(t_c) = sum_j c_j (t_c − centre_c)^j``, Horner's scheme over the stored columns."""
    dt = t_c - CalibrationParameter.centre_c
    expr: ColumnElement[float] = _c(MAX_DEGREE)
    for j in range(MAX_DEGREE - 1, -1, -1):
        expr = _c(j) + dt * expr
    return expr


def slope_at(t_c: float) -> ColumnElement[float]:
    """``dp/dT(t_c) = sum_j j c_j (t_c − centre_c)^(j−1)``, Horner's scheme."""
    dt = t_c - CalibrationParameter.centre_c
    expr: ColumnElement[float] = MAX_DEGREE * _c(MAX_DEGREE)
    for j in range(MAX_DEGREE - 1, 0, -1):
        expr = j * _c(j) + dt * expr
    return expr


def _c(j: int) -> ColumnElement[float]:
    return func.coalesce(getattr(CalibrationParameter, f"c{j}"), 0.0)


def store_rows(connection: Connection, calibration: Calibration) -> None:
    """(Re)write one calibration's rows, on the connection that writes the calibration."""
    connection.execute(delete(CalibrationParameter)
                       .where(CalibrationParameter.calibration_id == calibration.id))
    rows = parameter_rows(calibration.id, calibration.sensor, calibration.model)
    if rows:
        connection.execute(insert(CalibrationParameter), rows)


def backfill(connection: Connection) -> int:
    """Rows for every calibration that has none yet (stored without the ORM); how many."""
    done = select(CalibrationParameter.calibration_id).distinct()
    ids = connection.execute(select(Calibration.id).where(Calibration.id.not_in(done))
                             .order_by(Calibration.id)).scalars().all()
    for start in range(0, len(ids), BACKFILL_BATCH):
        batch = ids[start:start + BACKFILL_BATCH]
        rows = []
        for cal_id, sensor, doc in connection.execute(
                select(Calibration.id, Calibration.sensor, Calibration.model)
                .where(Calibration.id.in_(batch))):
            rows.extend(parameter_rows(cal_id, sensor, doc))
        if rows:
            connection.execute(insert(CalibrationParameter), rows)
    return len(ids)


@event.listens_for(Calibration, "after_insert")
def _after_insert(_mapper: Any, connection: Connection, target: Calibration) -> None:
    store_rows(connection, target)


@event.listens_for(Calibration, "after_update")
def _after_update(_mapper: Any, connection: Connection, target: Calibration) -> None:
    state = inspect(target)
    if any(state.attrs[k].history.has_changes() for k in ("model", "sensor")):
        store_rows(connection, target)
