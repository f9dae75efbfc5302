"""Several sensors per campaign through the engine and the sim twin (issue 12)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from engine_helpers import SMALL_SPEC, add_campaign, cursor_of, fake_calibrate
from sqlalchemy import select

from drivers.clock import VirtualClock
from drivers.geometry import angles_for_reference
from service.db.models import Calibration, Campaign, Measurement
from service.engine import store
from service.engine.identity import SerialBinding
from service.engine.rigs import RigDevices
from service.engine.runner import CampaignRunner
from simulators.rig import connect_rig, connect_sensors, start_sim_rig

SERIALS = ["SN-M1", "SN-M2", "SN-M3"]
SPEC = {**SMALL_SPEC, "setpoints_c": [0.0, 20.0], "soak_min": 20, "sensors": SERIALS}


def _set_sensor(sf, cid: int, serial: str) -> None:  # type: ignore[no-untyped-def]
    with sf() as s:
        s.get(Campaign, cid).sensor = serial
        s.commit()


async def _run(sf, cid: int, *, break_sensor=None, binding: str = "any",  # type: ignore[no-untyped-def]
               stop_at: int | None = None):
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=5, serials=SERIALS, modbus_in_memory=True) as sim:
        chamber, table, first = await connect_rig(sim, clock)
        await first.close()
        accels = connect_sensors(sim, clock)
        if break_sensor is not None:
            break_sensor(sim, accels)
        devices = RigDevices(chamber, table, accels[SERIALS[0]],
                             lambda ref: tuple(angles_for_reference(np.asarray(ref), 3)),
                             SerialBinding(binding), accelerometers=accels)  # type: ignore[arg-type]
        try:
            task = asyncio.create_task(CampaignRunner(sf, cid, devices, clock,
                                                      calibrate=fake_calibrate).run())
            while stop_at is not None and not task.done():
                # anywhere in the sweep of that step (a poll can miss a narrower window)
                if cursor_of(sf, cid)[:2] == (stop_at, "positions"):
                    break
                await asyncio.sleep(0.0005)
            if stop_at is not None:
                assert not task.done(), "campaign ended before the interruption point"
                # The in-process stand-in for SIGKILL: one cancel must end the run (pymodbus'
                # asyncio.wait_for used to drop a cancel that met a reply; modbus_link.py).
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await asyncio.wait_for(task, 30.0)
                state = "interrupted"
            else:
                state = await task
        finally:
            for dev in (chamber.link, table.link, *accels.values()):
                await dev.close()
    return state


async def test_every_sensor_is_read_at_every_position_and_calibrated(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, SPEC)
    _set_sensor(sf, cid, SERIALS[0])
    assert await _run(sf, cid) == "completed"
    with sf() as s:
        rows = s.execute(select(Measurement.sensor, Measurement.step, Measurement.position,
                                Measurement.ax).where(Measurement.campaign_id == cid)).all()
        camp = s.get(Campaign, cid)
        cals = s.scalars(select(Calibration).where(Calibration.campaign_id == cid)).all()
    assert len(rows) == 3 * 2 * 6
    for serial in SERIALS:
        mine = {(st, p) for se, st, p, _ in rows if se == serial}
        assert mine == {(st, p) for st in range(2) for p in range(6)}
    # each sensor is its own part: the same position reads differently
    ax = {se: a for se, st, p, a in rows if (st, p) == (0, 0)}
    assert len({round(v, 4) for v in ax.values()}) == 3
    assert sorted(c.sensor for c in cals) == sorted(SERIALS)
    assert set(camp.calibration_ids) == set(SERIALS)
    assert camp.calibration_id == camp.calibration_ids[SERIALS[0]]
    assert not camp.sensors_dropped
    assert store.measured_positions(sf, cid) == {(st, p) for st in range(2) for p in range(6)}


async def test_a_silent_sensor_is_dropped_with_its_reason_and_the_others_go_on(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, {**SPEC, "retry_backoff_s": 0.1})
    _set_sensor(sf, cid, SERIALS[0])

    def silence(sim, accels) -> None:  # type: ignore[no-untyped-def]
        sim.sensors[1].faults.p_no_reply = 1.0  # the bridge times out on every request
        # It never answers, so how long its driver waits (wall time) changes nothing but the
        # test's duration: 4 tries x 0.2 s instead of 4 x 2 s. The others keep the default.
        accels["SN-M2"].timeout_s = 0.2

    assert await _run(sf, cid, break_sensor=silence) == "completed"
    with sf() as s:
        camp = s.get(Campaign, cid)
        serials = set(s.scalars(select(Measurement.sensor)
                                .where(Measurement.campaign_id == cid)).all())
    assert set(camp.sensors_dropped) == {"SN-M2"}
    assert "no answer after 4 tries" in camp.sensors_dropped["SN-M2"]
    assert serials == {"SN-M1", "SN-M3"}
    assert set(camp.calibration_ids) == {"SN-M1", "SN-M3"}


async def test_a_wrong_identity_is_dropped_naming_both_serials(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, SPEC)
    _set_sensor(sf, cid, SERIALS[0])

    def swap(sim, accels) -> None:  # type: ignore[no-untyped-def]
        sim.sensors[2].bridge.eeprom_serial = "SN-OTHER"

    assert await _run(sf, cid, break_sensor=swap, binding="eeprom") == "completed"
    with sf() as s:
        camp = s.get(Campaign, cid)
    assert set(camp.sensors_dropped) == {"SN-M3"}
    reason = camp.sensors_dropped["SN-M3"]
    assert "SN-M3" in reason and "SN-OTHER" in reason
    assert set(camp.calibration_ids) == {"SN-M1", "SN-M2"}


async def test_resume_mid_sweep_stores_every_sensor_once(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, SPEC)
    _set_sensor(sf, cid, SERIALS[0])
    assert await _run(sf, cid, stop_at=1) == "interrupted"
    with sf() as s:
        partial = s.execute(select(Measurement.step, Measurement.position, Measurement.sensor)
                            .where(Measurement.campaign_id == cid)).all()
    # a position is stored for all three sensors or for none (one transaction)
    per_position: dict[tuple[int, int], int] = {}
    for st, p, _se in partial:
        per_position[(st, p)] = per_position.get((st, p), 0) + 1
    assert set(per_position.values()) == {3} and len(per_position) < 12
    assert await _run(sf, cid) == "completed"  # a new process: new clock, new rig
    with sf() as s:
        rows = s.execute(select(Measurement.step, Measurement.position, Measurement.sensor)
                         .where(Measurement.campaign_id == cid)).all()
    assert len(rows) == len(set(rows)) == 3 * 2 * 6


async def _acquire_s(sf, serials: list[str]) -> list[float]:  # type: ignore[no-untyped-def]
    """Clock time of every Acquire of a one-step campaign reading ``serials`` (one: alone)."""
    from calibration.campaign_plan import Acquire

    spec = {**SMALL_SPEC, "setpoints_c": [20.0], "soak_min": 2, "stability": "fixed",
            "samples_per_position": 1000}  # 16 s per capture at 62.5 Hz
    if len(serials) > 1:
        spec["sensors"] = serials
    cid = add_campaign(sf, spec)
    _set_sensor(sf, cid, serials[0])
    # Captures that overlap are timed: the clock moves only when the loop and the serial
    # reads are quiet, so a reply in flight on a loaded machine cannot serialise them.
    clock = VirtualClock(idle="loop")
    times: list[float] = []
    several = serials if len(serials) > 1 else ()
    async with start_sim_rig(clock, seed=5, serials=several, modbus_in_memory=True) as sim:
        chamber, table, first = await connect_rig(sim, clock)
        accels = {}
        if several:
            await first.close()
            accels = connect_sensors(sim, clock)
            first = accels[serials[0]]
        devices = RigDevices(chamber, table, first,
                             lambda ref: tuple(angles_for_reference(np.asarray(ref), 3)),
                             accelerometers=accels)  # type: ignore[arg-type]
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        runner.subscribe(lambda m, t0, t1: times.append(t1 - t0) if isinstance(m, Acquire)
                         else None)
        try:
            assert await runner.run() == "completed"
        finally:
            for dev in (chamber.link, table.link, *(accels.values() or [first])):
                await dev.close()
    return times


async def test_eight_sensors_are_read_at_once_not_one_after_the_other(sf) -> None:  # type: ignore[no-untyped-def]
    one = await _acquire_s(sf, ["SN-ONE"])
    eight = await _acquire_s(sf, [f"SN-C{i}" for i in range(8)])
    assert len(one) == len(eight) == 6
    capture_s = 1000 / 62.5
    assert min(one) >= capture_s  # the bridge's capture takes its time on the clock
    # Read one after the other, eight would take ≥ 8 × 16 s; at once, about one capture.
    assert np.mean(eight) < 2.0 * np.mean(one)
