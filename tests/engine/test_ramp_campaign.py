"""A ramp campaign on the wire twin: legs, sweeps with die temperatures, a continuous fit,
and a resume that skips the stored sweeps (calibration/ramp_plan.py, service/engine/ramp.py)."""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
from engine_helpers import (
    POSE_COLUMNS,
    SQLITE_ONLY,
    add_campaign,
    assert_poses_give_references,
    fake_calibrate,
)
from sqlalchemy import func, select

from calibration.ramp_plan import legs_done_from, ramp_legs
from calibration.recording import Recording, write_recording
from drivers.clock import VirtualClock
from service.cli import main
from service.db.models import Calibration, Campaign, Measurement
from service.engine import store
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner

# Ambient 23 °C → 20 → 28 → back to 23 at 2 °C/min; a 2-min die: short holds.
SPEC = {"method": "ramp", "setpoints_c": [20.0, 28.0], "positions": "six",
        "samples_per_position": 20, "ramp_c_per_min": 2.0, "settle_s": 1.0}
SIM = {"name": "sim", "chamber": {"driver": "sim", "range_c": [-70, 180]}}
OPTIONS = {"modbus_in_memory": True, "die_tau_s": 120.0}


async def _run(sf, cid: int, stop_after_rows: int | None = None,  # type: ignore[no-untyped-def]
               **kw) -> str:
    clock = VirtualClock()
    async with open_rig(SIM, clock, seed=3, sim_options=OPTIONS) as dev:
        task = asyncio.create_task(CampaignRunner(sf, cid, dev, clock, **kw).run())
        while stop_after_rows is not None and not task.done():
            with sf() as s:
                n = s.scalar(select(func.count()).select_from(Measurement)
                             .where(Measurement.campaign_id == cid))
            if n >= stop_after_rows:
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await asyncio.wait_for(task, 30.0)
                return "interrupted"
            await asyncio.sleep(0.001)
        return await task


def _rows(sf, cid: int) -> dict[str, np.ndarray]:  # type: ignore[no-untyped-def]
    return {k: np.asarray(v, float) for k, v in store.measurement_columns(sf, cid).items()}


@SQLITE_ONLY
async def test_a_ramp_campaign_sweeps_while_the_chamber_moves_and_is_fitted_continuously(
        sf, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, SPEC)
    assert await _run(sf, cid) == "completed"
    rows = _rows(sf, cid)
    # The legs, in order, in the stored setpoints in force: 20 (cold end first, held there),
    # 28 (held), then ramping back towards 23.
    sp = rows["setpoint_c"]
    first_cold, first_hot = np.flatnonzero(sp == 20.0)[0], np.flatnonzero(sp == 28.0)[0]
    assert 0 < first_cold < first_hot and np.all(sp[first_hot:] >= 23.0 - 1e-9)
    assert np.all(np.diff(sp[:first_cold + 1]) <= 0)
    assert np.all(np.diff(sp[first_cold:first_hot + 1]) >= 0)
    assert legs_done_from(sp, ramp_legs(SPEC["setpoints_c"], 23.0, 23.0)) == 2
    # Many sweeps of the six positions, each a step index; every capture with its die and air.
    sweeps = np.unique(rows["step"])
    assert sweeps.size >= 8 and set(np.unique(rows["position"])) == set(range(6))
    assert np.all(np.isfinite(rows["sensor_c"])) and np.all(np.isfinite(rows["chamber_c"]))
    # The die covered the range within the edge gap (hold at the turnarounds), channel
    # offset aside: the span of sensor_c is the range's 8 °C less at most 2 × 1 °C.
    assert np.ptp(rows["sensor_c"]) >= 8.0 - 2.0
    # The chamber moved during sweeps: most sweeps are not plateaus.
    moving = sum(np.ptp(rows["chamber_c"][rows["step"] == s]) > 0.5 for s in sweeps)
    assert moving >= sweeps.size // 2
    # The table stands still at each capture (move, settle, acquire) while the air ramps:
    # its commanded pose is known exactly and recorded (docs/recording.md, ``pose_q*``).
    with sf() as s:
        stored = s.scalars(select(Measurement).where(Measurement.campaign_id == cid)).all()
        assert_poses_give_references([{c: getattr(m, c) for c in (
            *POSE_COLUMNS, "ref_x", "ref_y", "ref_z")} for m in stored])
    with sf() as s:
        camp = s.get(Campaign, cid)
        cal = s.get(Calibration, camp.calibration_id)
        assert camp.progress["method"] == "ramp" and camp.progress["fraction"] == 1.0
        assert cal.model["method"] == "continuous"
        assert 5.0 < cal.rmse_ug < 40.0
        lo, hi = cal.valid_lo_c, cal.valid_hi_c
        coeffs = cal.model["polynomial"]["coefficients"]
    assert hi - lo >= 8.0 - 2.0 + 2.0  # coverage ± the 1 °C margin
    # The stored recording, calibrated again by `soakcal calibrate`: the same decision
    # (its sweeps are not plateaus: continuous) and the same model.
    csv, model = tmp_path / "ramp.csv", tmp_path / "model.json"
    write_recording(csv, Recording.from_columns(rows))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["calibrate", str(csv), "-o", str(model), "--json"]) == 0
    report = json.loads(out.getvalue())
    assert report["method"] == "continuous" and report["segmentation"]["continuous_rows"] > 0
    assert report["valid_c"] == pytest.approx([lo, hi], abs=1e-9)
    again = json.loads(model.read_text())["polynomial"]["coefficients"]
    assert again.keys() == coeffs.keys()
    for name in coeffs:
        assert np.allclose(np.asarray(again[name], float), np.asarray(coeffs[name], float),
                           rtol=1e-6, atol=1e-12), name


@SQLITE_ONLY
async def test_a_resumed_ramp_campaign_skips_the_stored_sweeps_and_continues_the_leg(
        sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, SPEC)
    assert await _run(sf, cid, stop_after_rows=40) == "interrupted"
    before = _rows(sf, cid)
    stored = set(zip(before["step"].astype(int), before["position"].astype(int), strict=True))
    assert await _run(sf, cid, calibrate=fake_calibrate) == "completed"
    after = _rows(sf, cid)
    pairs = list(zip(after["step"].astype(int), after["position"].astype(int), strict=True))
    assert len(pairs) == len(set(pairs))  # nothing measured twice
    assert stored <= set(pairs)
    # the sweep count continues after the stored ones, and campaign time too
    new = after["t_s"] > before["t_s"].max()
    assert after["step"][new].min() >= before["step"].max()
    assert legs_done_from(after["setpoint_c"], ramp_legs(SPEC["setpoints_c"], 23.0, 23.0)) == 2
