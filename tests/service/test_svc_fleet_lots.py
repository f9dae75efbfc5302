"""Lot statistics from the stored ``calibration_parameters`` rows, on SQLite and PostgreSQL.

The rows are written when a calibration is stored; the medians and MADs computed by the
database (PostgreSQL) and by numpy (the SQLite path) equal a direct numpy median/MAD of
the same polynomials evaluated at the reference temperature; a planted outlier is flagged.
"""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import insert, select

from service.api import fleet
from service.db.calibration_parameters import PARAMETERS, backfill
from service.db.models import Calibration, CalibrationParameter
from service.db.session import make_session_factory, session_scope

REFERENCE_C = 31.5
CENTRE_C = 20.0


def _doc(coefficients: dict[str, list[float]], valid_c: tuple[float, float] = (-10.0, 60.0)
         ) -> dict:  # type: ignore[type-arg]
    units = {n: (["1", "1/degC", "1/degC^2", "1/degC^3"] if n.startswith("s")
                 else ["g", "g/degC", "g/degC^2", "g/degC^3"]) for n in PARAMETERS}
    return {"temperature": {"centre_c": CENTRE_C, "valid_c": list(valid_c)},
            "polynomial": {"physical_coefficients": coefficients, "physical_units": units},
            "provenance": {"sensor_identity": {"reported_model": "ADXL357"}}}


def _random_coefficients(rng: np.random.Generator) -> dict[str, list[float]]:
    """Cubic polynomials with datasheet-sized spreads (bias mg, scale ppm, angles µrad)."""
    out = {}
    for name in PARAMETERS:
        c0 = (1.0 if name.startswith("s") else 0.0) + rng.normal(0.0, 2e-3)
        out[name] = [c0, rng.normal(1e-5, 3e-6), rng.normal(0.0, 2e-8), rng.normal(0.0, 1e-10)]
    return out


def _store(sf, serial: str, doc: dict) -> int:  # type: ignore[no-untyped-def,type-arg]
    with session_scope(sf) as session:
        row = Calibration(sensor=serial, valid_lo_c=-10.0, valid_hi_c=60.0, rmse_ug=20.0,
                          model_version="test", model=doc)
        session.add(row)
        session.flush()
        return row.id


def test_storing_a_calibration_stores_its_twelve_polynomials(clean_db_url: str) -> None:
    sf = make_session_factory(clean_db_url)
    coefficients = _random_coefficients(np.random.default_rng(1))
    cal_id = _store(sf, "SN-ROWS-1", _doc(coefficients))
    with sf() as session:
        rows = session.scalars(select(CalibrationParameter)
                               .where(CalibrationParameter.calibration_id == cal_id)).all()
    assert sorted(r.name for r in rows) == sorted(PARAMETERS)
    bx = next(r for r in rows if r.name == "bx")
    assert [bx.c0, bx.c1, bx.c2, bx.c3] == coefficients["bx"] and bx.c4 is None
    assert (bx.sensor, bx.reported_model, bx.centre_c, bx.valid_lo_c, bx.valid_hi_c) == (
        "SN-ROWS-1", "ADXL357", CENTRE_C, -10.0, 60.0)
    assert (bx.unit, bx.tempco_unit) == ("g", "g/degC")
    # a corrected model document rewrites them
    with session_scope(sf) as session:
        row = session.get(Calibration, cal_id)
        assert row is not None
        row.model = _doc({**coefficients, "bx": [0.5, 0.0]})
    with sf() as session:
        bx = session.get(CalibrationParameter, (cal_id, "bx"))
        assert bx is not None and (bx.c0, bx.c1, bx.c2) == (0.5, 0.0, None)


def test_calibrations_stored_without_the_orm_are_backfilled(clean_db_url: str) -> None:
    sf = make_session_factory(clean_db_url)
    doc = _doc(_random_coefficients(np.random.default_rng(2)))
    with session_scope(sf) as session:  # a bulk write: no ORM object, no listener
        session.execute(insert(Calibration), [
            {"sensor": f"SN-BULK-{i}", "valid_lo_c": -10.0, "valid_hi_c": 60.0,
             "rmse_ug": 20.0, "model_version": "test", "model": doc} for i in range(3)])
    with sf() as session:
        assert session.scalars(select(CalibrationParameter)).all() == []
    with session_scope(sf) as session:
        assert backfill(session.connection()) == 3
        assert backfill(session.connection()) == 0  # only what is missing
    with sf() as session:
        assert len(session.scalars(select(CalibrationParameter)).all()) == 3 * 12


def _expected(docs: list[dict]) -> dict[str, tuple[float, float]]:  # type: ignore[type-arg]
    """name → (median, 1.4826·MAD) straight from the polynomials, with numpy."""
    out = {}
    dt = REFERENCE_C - CENTRE_C
    for name in PARAMETERS:
        c = np.array([d["polynomial"]["physical_coefficients"][name] for d in docs])
        value = np.polynomial.polynomial.polyval(dt, c.T)
        slope = np.polynomial.polynomial.polyval(
            dt, np.array([np.polynomial.polynomial.polyder(ci) for ci in c]).T)
        for key, x in ((name, value), (f"d{name}/dT", slope)):
            median = float(np.median(x))
            out[key] = (median, 1.4826 * float(np.median(np.abs(x - median))))
    return out


def test_database_and_python_statistics_equal_numpy_and_flag_the_planted_outlier(
        clean_db_url: str) -> None:
    sf = make_session_factory(clean_db_url)
    rng = np.random.default_rng(23)
    docs = [_doc(_random_coefficients(rng)) for _ in range(40)]
    docs[17]["polynomial"]["physical_coefficients"]["by"][0] += 0.1  # 100 mg off its lot
    ids = [_store(sf, f"SN-NUM-{i:02d}", d) for i, d in enumerate(docs)]
    _store(sf, "SN-NUM-COLD", _doc(_random_coefficients(rng), valid_c=(-40.0, 0.0)))
    expected = _expected(docs)
    with sf() as session:
        values, units = fleet._values(session, REFERENCE_C, None)
        paths = {"python": fleet._spreads_in_python(values, units)}
        if session.get_bind().dialect.name == "postgresql":
            paths["sql"] = fleet._spreads_in_sql(session, REFERENCE_C)
    for path, (spreads, flags) in paths.items():
        (lot_spreads,) = spreads.values()
        assert [s.name for s in lot_spreads][:4] == ["bx", "dbx/dT", "by", "dby/dT"], path
        assert {s.name: s.n for s in lot_spreads} == {k: 40 for k in expected}, path
        for s in lot_spreads:
            assert (s.median, s.sigma) == pytest.approx(expected[s.name], rel=1e-9,
                                                         abs=1e-15), (path, s.name)
        (lot_flags,) = flags.values()
        assert [(f.sensor, f.calibration_id, f.name) for f in lot_flags] == [
            ("SN-NUM-17", ids[17], "by")], path
        median, sigma = expected["by"]
        assert lot_flags[0].z == pytest.approx((lot_flags[0].value - median) / sigma, abs=0.05)
        assert lot_flags[0].z > 4.0
    with sf() as session:
        ((lot, members),) = fleet._lots(session, REFERENCE_C)
    assert (lot.model, lot.sensors, lot.left_out) == ("ADXL357", 40, ["SN-NUM-COLD"])
    assert members == set(ids)
    assert [(f.sensor, f.name) for f in lot.flags] == [("SN-NUM-17", "by")]


def test_a_document_of_another_shape_is_stored_without_rows_it_cannot_read(
        clean_db_url: str) -> None:
    sf = make_session_factory(clean_db_url)
    coefficients = _random_coefficients(np.random.default_rng(3))
    coefficients["bx"] = ["0.001", 0.0]  # a string is not a coefficient
    coefficients["by"] = [None]  # type: ignore[list-item]  # a null, as JSON has no NaN
    odd = _store(sf, "SN-ODD-1", _doc(coefficients))
    bare = _store(sf, "SN-ODD-2", {"polynomial": "cubic", "temperature": [20.0]})
    with sf() as session:
        names = session.scalars(select(CalibrationParameter.name)
                                .where(CalibrationParameter.calibration_id == odd)).all()
        assert sorted(names) == sorted(set(PARAMETERS) - {"bx", "by"})
        assert session.scalars(select(CalibrationParameter)
                               .where(CalibrationParameter.calibration_id == bare)).all() == []
        assert session.get(Calibration, bare) is not None
