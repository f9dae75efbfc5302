"""The plan over a persisted cursor, on in-process fakes and a VirtualClock."""

from __future__ import annotations

import asyncio
import dataclasses
from collections import Counter
from typing import Any

import pytest
from engine_fakes import Faults, make_fake_rig
from engine_helpers import (
    SMALL_SPEC,
    SQLITE_ONLY,
    add_campaign,
    cursor_of,
    fake_calibrate,
    n_measurements,
)
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Calibration, Campaign, Measurement
from service.engine.runner import CampaignRunner

N_STEPS, N_POS = 3, 6


def measurements(sf, cid):  # type: ignore[no-untyped-def]
    with sf() as s:
        return s.execute(select(Measurement).where(Measurement.campaign_id == cid)
                         .order_by(Measurement.t_s)).scalars().all()


def campaign(sf, cid) -> Campaign:  # type: ignore[no-untyped-def]
    with sf() as s:
        c = s.get(Campaign, cid)
        s.expunge(c)
        return c


async def run(sf, cid, rig, clock, timeout_s: float = 30.0) -> str:  # type: ignore[no-untyped-def]
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate)
    return await asyncio.wait_for(runner.run(), timeout_s)


def assert_complete_once(sf, cid) -> None:  # type: ignore[no-untyped-def]
    rows = measurements(sf, cid)
    counts = Counter((m.step, m.position) for m in rows)
    assert set(counts) == {(s, p) for s in range(N_STEPS) for p in range(N_POS)}
    assert max(counts.values()) == 1
    t = [m.t_s for m in rows]
    assert t == sorted(t)


async def test_small_campaign_completes_with_every_position_once(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    assert await run(sf, cid, rig, clock) == "completed"
    assert_complete_once(sf, cid)
    c = campaign(sf, cid)
    assert c.calibration_id is not None and c.finished_at is not None
    assert c.progress["fraction"] == 1.0 and c.progress["steps"] == N_STEPS
    assert [e["step"] for e in c.steps_log] == [0, 1, 2]
    assert all(e["reason"] in ("die_predicted_within_tol", "die_flat") for e in c.steps_log)
    assert all(e["tau_s"] is None or e["tau_s"] > 0 for e in c.steps_log)
    with sf() as s:
        assert s.get(Calibration, c.calibration_id).campaign_id == cid
    # Chamber left at a safe temperature, table home.
    assert rig.chamber.setpoints_c[-1] == 23.0 and rig.turntable.angles == (0.0, 0.0)
    # The die was within tolerance of the air when each position was measured.
    rows = measurements(sf, cid)
    assert all(m.attempts == 1 and m.flags is None for m in rows)


@SQLITE_ONLY
async def test_predictive_soak_is_shorter_than_fixed_at_equal_die_error(sf) -> None:
    soaks = {}
    for policy in ("predictive", "fixed"):
        clock = VirtualClock(idle_wall_s=0.0)
        rig = make_fake_rig(clock)
        cid = add_campaign(sf, {**SMALL_SPEC, "soak_min": 60, "stability": policy})
        assert await run(sf, cid, rig, clock) == "completed"
        soaks[policy] = sum(e["soak_s"] for e in campaign(sf, cid).steps_log)
        # die - air at measurement time: compare on the stored rows (sensor offset removed)
    assert soaks["fixed"] == pytest.approx(3 * 3600.0, abs=3 * 61.0)
    assert soaks["predictive"] < soaks["fixed"]


@pytest.mark.parametrize(("phase", "step"), [("ramp", 1), ("soak", 1), ("positions", 1),
                                           ("positions", 2), ("fitting", 2)])
async def test_resume_after_interruption_in_every_phase_loses_and_duplicates_nothing(
    sf, phase: str, step: int
) -> None:
    """Interrupt when the cursor reaches (step, phase); resume in a new runner and clock."""
    cid = add_campaign(sf)
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    slow = SlowCalibrate()
    task = asyncio.create_task(
        CampaignRunner(sf, cid, rig.devices, clock, calibrate=slow).run())

    def reached() -> bool:
        at_step, at_phase, at_position = cursor_of(sf, cid)
        return (at_step, at_phase) == (step, phase) and (
            phase != "positions" or at_position >= 3)

    while not reached():
        assert not task.done(), "campaign ended before reaching the interruption point"
        await asyncio.sleep(0.0005)
    task.cancel()  # the in-process stand-in for SIGKILL: no cleanup writes to the DB
    with pytest.raises(asyncio.CancelledError):
        await task
    c = campaign(sf, cid)
    assert c.state == "running" and c.calibration_id is None
    clock2 = VirtualClock(idle_wall_s=0.0)  # a new process: a new clock from zero
    rig2 = make_fake_rig(clock2)
    assert await run(sf, cid, rig2, clock2) == "completed"
    assert_complete_once(sf, cid)
    assert len(campaign(sf, cid).steps_log) == N_STEPS


class SlowCalibrate:
    """A calibration core that takes a while (so a test can interrupt the fitting phase)."""

    def __call__(self, columns, provenance):  # type: ignore[no-untyped-def]
        import time

        time.sleep(0.05)
        return fake_calibrate(columns, provenance)


async def test_resume_in_a_step_resoaks_before_measuring(sf) -> None:
    cid = add_campaign(sf)
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    task = asyncio.create_task(CampaignRunner(sf, cid, rig.devices, clock,
                                              calibrate=fake_calibrate).run())
    while n_measurements(sf, cid) < 9:  # mid step 1
        await asyncio.sleep(0.001)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    clock2 = VirtualClock(idle_wall_s=0.0)
    rig2 = make_fake_rig(clock2)  # a cold chamber at 23 °C: the step must be re-ramped and soaked
    assert await run(sf, cid, rig2, clock2) == "completed"
    assert_complete_once(sf, cid)
    log = {e["step"]: e for e in campaign(sf, cid).steps_log}
    assert log[1]["resumed"] is True
    assert rig2.chamber.setpoints_c[0] == SMALL_SPEC["setpoints_c"][1]
    # The first re-measured row of step 1 was taken with the die near the air again.
    rows = [m for m in measurements(sf, cid) if m.step == 1]
    assert abs(rows[-1].chamber_c - SMALL_SPEC["setpoints_c"][1]) < 0.3


async def test_quality_failure_remeasures_once_then_flags(sf) -> None:
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [20.0]})
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)

    # The first two full captures are noisy: position 0 is re-measured, then flagged.
    orig = rig.accelerometer.acquire

    async def acquire(n):  # type: ignore[no-untyped-def]
        if n == SMALL_SPEC["samples_per_position"] and acquire.left > 0:
            acquire.left -= 1
            rig.accelerometer.bad_captures = 1
        return await orig(n)

    acquire.left = 2
    rig.accelerometer.acquire = acquire  # type: ignore[method-assign]
    assert await run(sf, cid, rig, clock) == "completed"
    rows = {m.position: m for m in measurements(sf, cid)}
    assert rows[0].attempts == 2 and rows[0].flags == "noise_sd"
    assert all(rows[p].attempts == 1 and rows[p].flags is None for p in range(1, N_POS))


@SQLITE_ONLY
async def test_retryable_faults_on_five_percent_of_calls_do_not_hurt(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    faults = Faults(p_fail=0.05)
    rig = make_fake_rig(clock, faults)
    cid = add_campaign(sf)
    assert await run(sf, cid, rig, clock) == "completed"
    assert faults.raised > 5
    assert_complete_once(sf, cid)
    assert campaign(sf, cid).suspended_reason is None


async def test_outage_suspends_then_recovers(sf, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0)
    # The chamber stops answering for 20 min during the first soak.
    faults = Faults(outages=[(2000.0, 3200.0, "chamber")])
    rig = make_fake_rig(clock, faults)
    cid = add_campaign(sf)
    # Every suspended_reason the runner writes, in order: polling the row from the test
    # missed the 20 virtual minutes when the machine was loaded (the clock does not wait).
    from service.engine import store

    seen: list[str | None] = []
    update = store.update_campaign

    def recording_update(sf_: Any, cid_: int, **fields: Any) -> Any:
        if "suspended_reason" in fields:
            seen.append(fields["suspended_reason"])
        return update(sf_, cid_, **fields)

    monkeypatch.setattr(store, "update_campaign", recording_update)
    assert await run(sf, cid, rig, clock) == "completed"
    assert any(r and "chamber" in r for r in seen), seen
    assert seen[-1] is None  # cleared once the chamber answered again
    assert campaign(sf, cid).suspended_reason is None
    assert_complete_once(sf, cid)


async def test_outage_longer_than_suspend_limit_fails(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    faults = Faults(outages=[(2000.0, 1e9, "chamber")])
    rig = make_fake_rig(clock, faults)
    cid = add_campaign(sf, {**SMALL_SPEC, "suspend_limit_s": 600.0})
    assert await run(sf, cid, rig, clock) == "failed"
    c = campaign(sf, cid)
    assert "did not recover" in c.error and c.finished_at is not None


async def test_max_soak_policy(sf) -> None:
    for policy, final in (("continue", "completed"), ("fail", "failed")):
        clock = VirtualClock(idle_wall_s=0.0)
        rig = make_fake_rig(clock, drift_c=1.0)  # the air swings ±1 °C: never settles
        cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [20.0], "on_max_soak": policy})
        assert await run(sf, cid, rig, clock) == final
        log = campaign(sf, cid).steps_log
        assert log[0]["max_soak_reached"] is True and log[0]["reason"] == "max_soak_reached"
        assert log[0]["soak_s"] >= 2 * 30 * 60


async def test_crash_during_fitting_resumes_to_calibration_without_remeasuring(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    assert await run(sf, cid, rig, clock) == "completed"
    # Rewind to "killed while fitting": all rows stored, no calibration linked yet.
    from service.engine import store

    store.update_campaign(sf, cid, state="running", calibration_id=None, finished_at=None,
                          cursor_phase="fitting")
    n_acq = rig.accelerometer.acquisitions
    assert await run(sf, cid, rig, clock) == "completed"
    assert rig.accelerometer.acquisitions == n_acq  # nothing measured again
    assert campaign(sf, cid).calibration_id is not None
    assert_complete_once(sf, cid)


async def test_a_one_sensor_fit_failure_fails_the_campaign_with_its_reason(sf) -> None:  # type: ignore[no-untyped-def]
    # One sensor is a list of one: its fault is the campaign's, told as it is, never
    # "every sensor dropped", and nothing is flagged as dropped.
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [20.0]})

    def broken_fit(columns, provenance):  # type: ignore[no-untyped-def]
        raise ValueError("singular normal matrix")

    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=broken_fit)
    assert await asyncio.wait_for(runner.run(), 30.0) == "failed"
    c = campaign(sf, cid)
    assert c.error == "calibration fit failed: singular normal matrix"
    assert not c.sensors_dropped and c.calibration_id is None


async def test_a_one_sensor_reading_out_of_range_fails_naming_the_reading(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    acquire = rig.devices.accelerometer.acquire

    async def dead_z(n_samples: int) -> Any:
        acq = await acquire(n_samples)
        return dataclasses.replace(acq, mean_g=(acq.mean_g[0], acq.mean_g[1], 0.0))

    rig.devices.accelerometer.acquire = dead_z  # type: ignore[method-assign]
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [20.0]})
    assert await run(sf, cid, rig, clock) == "failed"
    c = campaign(sf, cid)
    assert c.error.startswith("reading out of range: |a| = "), c.error
    assert "dropped" not in c.error and not c.sensors_dropped
    # the first position whose gravity lies on z is where it fails: nothing stored after it
    assert all(abs(m.ref_z) < 0.5 for m in measurements(sf, cid))


async def test_a_controller_without_a_working_setpoint_arrives_on_its_pv(sf) -> None:  # type: ignore[no-untyped-def]
    # Some controllers have no working-setpoint register (ChamberStatus.working_setpoint_c
    # None): the ramp has arrived once the PV is within the stability tolerance.
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    read = rig.devices.chamber.read_status

    async def no_wsp() -> Any:
        return dataclasses.replace(await read(), working_setpoint_c=None)

    rig.devices.chamber.read_status = no_wsp  # type: ignore[method-assign]
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [-10.0, 20.0]})
    assert await run(sf, cid, rig, clock) == "completed"
    rows = measurements(sf, cid)
    assert len(rows) == 2 * N_POS
    assert all(abs(m.chamber_c - (-10.0, 20.0)[m.step]) < 2.0 for m in rows)
