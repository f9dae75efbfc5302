"""Helpers shared by the engine tests: campaign rows and a fake calibration core."""

from __future__ import annotations

from typing import Any

import pytest
from sqlalchemy import func, select

from calibration.table_pose import POSE_COLUMNS
from service.db.models import Campaign, Measurement, Rig
from service.engine.calibrate import CalibrationRow

# For tests of device and engine logic (Modbus faults, safe states, suspenders, register maps):
# their store calls are the ones test_runner, test_control and test_crash run on both backends,
# so a second, PostgreSQL run of the same campaign adds time and no check. Tests of the store,
# the lease or the control channel keep tests/conftest.py's two backends.
SQLITE_ONLY = pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)

SMALL_SPEC: dict[str, Any] = {
    "setpoints_c": [-10.0, 10.0, 30.0],
    "soak_min": 30,
    "positions": "six",
    "samples_per_position": 50,
    "ramp_c_per_min": 2.0,
}


def add_campaign(sf, spec: dict[str, Any] | None = None, rig: str = "sim",  # type: ignore[no-untyped-def]
                 state: str = "queued") -> int:
    with sf() as s:
        if s.query(Rig).filter_by(name=rig).first() is None:
            s.add(Rig(name=rig, chamber={"driver": "sim", "range_c": [-70, 180]},
                      turntable={"driver": "sim"}, sensors=[]))
            s.flush()
        c = Campaign(rig=rig, sensor="SN-T", spec=dict(spec or SMALL_SPEC), state=state,
                     progress={}, steps_log=[])
        s.add(c)
        s.commit()
        return c.id


def cursor_of(sf, cid: int) -> tuple[int | None, str | None, int | None]:  # type: ignore[no-untyped-def]
    """The campaign's cursor (step, phase, position) on a bare connection.

    For the loops that poll a running campaign every millisecond or less on the runner's
    own event loop: an ORM session per poll (~1-3 ms) was most of those tests' CPU and
    held the runner back; a bare connection reads the same columns in ~0.3 ms (as
    ``store.read_control`` does for the engine)."""
    with sf.kw["bind"].connect() as conn:
        row = conn.execute(select(Campaign.cursor_step, Campaign.cursor_phase,
                                  Campaign.cursor_position).where(Campaign.id == cid)).one()
        return row[0], row[1], row[2]


def n_measurements(sf, cid: int) -> int:  # type: ignore[no-untyped-def]
    """How many measurement rows the campaign has, counted by the database (for polling
    loops; ``cursor_of`` says why not through the ORM)."""
    with sf.kw["bind"].connect() as conn:
        return int(conn.execute(select(func.count()).select_from(Measurement)
                                .where(Measurement.campaign_id == cid)).scalar_one())


def fake_calibrate(columns, provenance):  # type: ignore[no-untyped-def]
    """A stand-in for the calibration core: fast, and records what it was given."""
    fake_calibrate.calls.append(len(columns["t_s"]))
    return CalibrationRow(valid_lo_c=min(columns["sensor_c"]),
                          valid_hi_c=max(columns["sensor_c"]), rmse_ug=1.0,
                          model_version="fake", model={"fake": True}, report={},
                          provenance=provenance)


fake_calibrate.calls = []  # type: ignore[attr-defined]


def assert_poses_give_references(rows: list[dict[str, Any]], atol: float = 1e-9) -> None:
    """Every row's recorded pose (docs/recording.md, ``pose_q*``) is a unit quaternion with
    ``qw ≥ 0`` whose ``|g| Rᵀ (0, 0, 1)`` is the row's ``ref_*``."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    assert rows
    for row in rows:
        q = np.array([float(row[c]) for c in POSE_COLUMNS])
        ref = np.array([float(row[c]) for c in ("ref_x", "ref_y", "ref_z")])
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12 and q[0] >= 0.0, q
        R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
        np.testing.assert_allclose(np.linalg.norm(ref) * R.T @ [0.0, 0.0, 1.0], ref, atol=atol)
