"""Fenced rows: a process that lost its rig lease writes nothing for its campaign.

The runner's store calls go through ``store.fenced_sessions``: every transaction
that writes confirms the lease in itself, and reads do not. Run on SQLite and,
with SOAKCAL_TEST_DATABASE_URL, on PostgreSQL.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from engine_fakes import make_fake_rig
from engine_helpers import add_campaign, fake_calibrate
from sqlalchemy import event, func, select, update

from drivers.clock import VirtualClock
from service.db.models import Calibration, Campaign, Measurement, RigLease, SoakProbe
from service.engine import store
from service.engine.calibrate import CalibrationRow
from service.engine.manager import CampaignManager
from service.engine.runner import CampaignRunner

FENCE = store.Fence("sim", "proc-a")
PROBE = {"sensor": "SN-T", "step": 0, "soak_start_t_s": 0.0, "pose": "0.0,0.0", "t_s": 5.0,
         "setpoint_c": -10.0, "chamber_c": -9.0, "sensor_c": -5.0, "ref_x": 0.0,
         "ref_y": 0.0, "ref_z": 1.0, "ax": 0.0, "ay": 0.0, "az": 1.0, "n": 8}
CALIBRATION = {"valid_lo_c": -10.0, "valid_hi_c": 30.0, "rmse_ug": 1.0,
               "model_version": "fake", "model": {}, "report": {}, "provenance": {}}


def take_over(sf: Any) -> None:
    with sf() as s:  # proc-b took the rig over while proc-a was stalled
        s.execute(update(RigLease).where(RigLease.rig == "sim").values(owner="proc-b"))
        s.commit()


def snapshot(sf: Any, cid: int) -> dict[str, Any]:
    """Everything the runner writes for a campaign, as a person would compare it."""
    with sf() as s:
        c = s.get(Campaign, cid)
        count = lambda model: s.scalar(  # noqa: E731
            select(func.count()).select_from(model).where(model.campaign_id == cid))
        return {"state": c.state, "progress": c.progress, "steps_log": c.steps_log,
                "cursor": (c.cursor_step, c.cursor_phase, c.cursor_position),
                "suspended_reason": c.suspended_reason, "sensors_dropped": c.sensors_dropped,
                "probes": count(SoakProbe), "measurements": count(Measurement),
                "calibrations": count(Calibration)}


def lease_statements(sf: Any) -> list[str]:
    """Every SQL statement on rig_leases from now on (appended as they run)."""
    seen: list[str] = []

    def record(_conn: Any, _cursor: Any, statement: str, *_a: Any) -> None:
        if "rig_leases" in statement:
            seen.append(statement.split()[0].upper())

    event.listen(sf.kw["bind"], "before_cursor_execute", record)
    return seen


def test_every_write_confirms_the_lease_once_and_reads_do_not(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, state="running")
    assert CampaignManager(sf, owner="proc-a", lease_s=3600)._claim("sim", cid)
    fenced = store.fenced_sessions(sf, FENCE, cid)
    checks = lease_statements(sf)
    store.load_campaign(fenced, cid)
    store.measured_positions(fenced, cid)
    store.soak_probe_rows(fenced, cid)
    store.measurement_columns(fenced, cid)
    store.read_control(fenced, cid)
    assert checks == []  # reads pay nothing
    store.update_campaign(fenced, cid, progress={"phase": "soak"}, suspended_reason="x")
    store.set_cursor(fenced, cid, 0, "soak", 0)
    store.add_soak_probes(fenced, cid, [PROBE, {**PROBE, "t_s": 6.0}])
    store.put_step_log(fenced, cid, {"step": 0, "soak_s": 60.0})
    store.drop_sensor(fenced, cid, "SN-2", "no reply")
    assert store.store_calibration(fenced, cid, CalibrationRow(**CALIBRATION)) > 0
    assert store.transition(fenced, cid, "paused")
    assert checks == ["UPDATE"] * 7  # one confirmation per writing transaction
    got = snapshot(sf, cid)
    assert (got["state"], got["probes"], got["calibrations"]) == ("paused", 2, 1)
    assert got["steps_log"] == [{"step": 0, "soak_s": 60.0}]
    assert got["sensors_dropped"] == {"SN-2": "no reply"}


def test_a_process_that_lost_its_lease_writes_nothing(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, state="running")
    assert CampaignManager(sf, owner="proc-a", lease_s=3600)._claim("sim", cid)
    fenced = store.fenced_sessions(sf, FENCE, cid)
    store.update_campaign(fenced, cid, progress={"phase": "soak", "step": 0})
    take_over(sf)
    before = snapshot(sf, cid)
    lost = pytest.raises(store.LeaseLost, match="lease no longer held by proc-a")
    with lost:
        store.update_campaign(fenced, cid, progress={"phase": "soak", "step": 1})
    with lost:
        store.update_campaign(fenced, cid, suspended_reason="chamber.read_status: timeout")
    with lost:
        store.set_cursor(fenced, cid, 1, "soak", 0)
    with lost:
        store.add_soak_probes(fenced, cid, [PROBE])
    with lost:
        store.put_step_log(fenced, cid, {"step": 0, "soak_s": 60.0})
    with lost:
        store.drop_sensor(fenced, cid, "SN-2", "no reply")
    with lost:
        store.store_calibration(fenced, cid, CalibrationRow(**CALIBRATION))
    with lost:
        store.clear_action(fenced, cid, "resume")
    # A state change is refused as a lost race (False), never as an error a caller could
    # record as the campaign's failure with an unfenced session.
    assert store.transition(fenced, cid, "failed", error="engine error") is False
    assert snapshot(sf, cid) == before
    assert store.load_campaign(fenced, cid).progress == {"phase": "soak", "step": 0}


async def test_a_runner_stalled_before_a_probe_write_writes_nothing_after_the_takeover(
        sf) -> None:  # type: ignore[no-untyped-def]
    """proc-a stalls inside a soak probe's capture; proc-b takes the rig over meanwhile.
    The capture returns, and the probe row, the progress, the step log and the cursor that
    would follow are not written: the first write after it is refused in its transaction."""
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    assert CampaignManager(sf, owner="proc-a", lease_s=3600)._claim("sim", cid)
    acquire = rig.accelerometer.acquire
    at_takeover: dict[str, Any] = {}
    soak_captures = {"n": 0}

    async def stalled(n_samples: int) -> Any:
        reading = await acquire(n_samples)
        if not at_takeover and store.load_campaign(sf, cid).cursor_phase == "soak":
            soak_captures["n"] += 1
            if soak_captures["n"] == 3:  # two probes of this soak stored, then the stall
                take_over(sf)
                at_takeover.update(snapshot(sf, cid))
        return reading

    rig.accelerometer.acquire = stalled  # type: ignore[method-assign]
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate, fence=FENCE)
    assert await asyncio.wait_for(runner.run(), 30) == "running"  # left to proc-b
    assert at_takeover["probes"] >= 2  # it did write while it held the lease
    assert snapshot(sf, cid) == at_takeover
