"""Every exit of the engine leaves the twin's rig safe: chamber at 23 °C, table home and at rest.

Each test runs a campaign through the wire-level twin (Modbus chamber and
table servers, serial sensor bridge), ends it one way, then reads the
chamber's setpoint register and the table's status through a fresh
connection, as an operator's tool would.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from engine_helpers import SMALL_SPEC, SQLITE_ONLY, add_campaign, fake_calibrate
from sqlalchemy import select, update

from drivers import registermaps
from drivers.clock import VirtualClock
from service.db.models import Campaign, Measurement, RigLease
from service.engine import manager as manager_mod
from service.engine import store
from service.engine.manager import CampaignManager
from service.engine.rigs import RigDevices, open_rig
from service.engine.runner import CampaignRunner
from simulators.rig import connect_rig, start_sim_rig

SAFE_C = 23.0
SPEC: dict[str, Any] = {**SMALL_SPEC, "setpoints_c": [-40.0, 60.0, -40.0], "positions": "six",
                        "samples_per_position": 20}


def _cfg(sim: Any) -> dict[str, Any]:
    return {"name": "lab",
            "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": sim.chamber_map},
            "turntable": {"url": sim.table_url},
            # the twin reached by URL reports its own serial: bind any (as the sim rig does)
            "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}


@contextlib.asynccontextmanager
async def twin(clock: VirtualClock) -> AsyncIterator[tuple[Any, RigDevices]]:
    async with start_sim_rig(clock, seed=5) as sim, open_rig(_cfg(sim), clock) as devices:
        yield sim, devices


async def rig_state(sim: Any, clock: VirtualClock) -> tuple[float, Any]:
    """(chamber setpoint register °C, table status) once the table had time to get home."""
    await clock.sleep(120.0)
    chamber, table, sensor = await connect_rig(sim, clock)
    try:
        return (await chamber.read_status()).setpoint_c, await table.read_status()
    finally:
        await chamber.close()
        await table.close()
        with contextlib.suppress(Exception):
            await sensor.close()


def assert_safe(setpoint_c: float, table: Any) -> None:
    assert setpoint_c == pytest.approx(SAFE_C, abs=0.05)
    assert not table.moving and table.in_position
    assert max(abs(a) for a in table.angles_deg) < 0.05


def state_of(sf: Any, cid: int) -> Campaign:
    return store.load_campaign(sf, cid)


def n_measured(sf: Any, cid: int) -> int:
    with sf() as s:
        return len(s.execute(select(Measurement.id).where(Measurement.campaign_id == cid)).all())


async def until(pred: Any, timeout_s: float = 60.0) -> None:
    async def loop() -> None:
        while not pred():
            await asyncio.sleep(0.002)

    await asyncio.wait_for(loop(), timeout_s)


@SQLITE_ONLY
async def test_completed_campaign_ends_safe(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SPEC, "setpoints_c": [-40.0]}, rig="lab")
    async with twin(clock) as (sim, devices):
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        assert await asyncio.wait_for(runner.run(), 60) == "completed"
        assert_safe(*await rig_state(sim, clock))


@SQLITE_ONLY
async def test_the_chamber_maps_safe_setpoint_is_where_a_campaign_leaves_it(
        sf, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """The rig owns its safe state: a map whose [safe] says 10 °C gets 10 °C at the end
    (the campaign sets no safe_c); a campaign's own safe_c still wins."""
    text = (Path(registermaps.__file__).parent / "maps" / "eurotherm-3216.toml").read_text()
    assert "[safe]\nsetpoint_c = 23.0" in text
    cold = tmp_path / "cold-safe-3216.toml"
    cold.write_text(text.replace("[safe]\nsetpoint_c = 23.0", "[safe]\nsetpoint_c = 10.0"))
    for spec_safe_c, expected_c in ((None, 10.0), (15.0, 15.0)):
        clock = VirtualClock(idle_wall_s=0.0003)
        extra = {} if spec_safe_c is None else {"safe_c": spec_safe_c}
        cid = add_campaign(sf, {**SPEC, "setpoints_c": [-40.0], **extra}, rig="lab")
        async with start_sim_rig(clock, seed=5, chamber_map=str(cold)) as sim, \
                open_rig({**_cfg(sim), "chamber": {"driver": "modbus", "url": sim.chamber_url,
                                                   "map": str(cold)}}, clock) as devices:
            runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
            assert await asyncio.wait_for(runner.run(), 60) == "completed"
            setpoint_c, table = await rig_state(sim, clock)
        assert setpoint_c == pytest.approx(expected_c, abs=0.05)
        assert not table.moving and table.in_position


@SQLITE_ONLY
async def test_a_map_whose_safe_state_says_stop_gets_its_chamber_stopped(
        sf, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """[safe] stop = true: the park writes the safe setpoint, then stops the controller."""
    text = (Path(registermaps.__file__).parent / "maps" / "soakcal-twin-chamber.toml").read_text()
    stopping = tmp_path / "stopping-twin.toml"
    stopping.write_text(text.replace("[safe]\nsetpoint_c = 23.0",
                                     "[safe]\nsetpoint_c = 23.0\nstop = true"))
    assert registermaps.load_chamber_map(stopping).safe_stop
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SPEC, "setpoints_c": [-40.0]}, rig="lab")
    async with start_sim_rig(clock, seed=5, chamber_map=str(stopping)) as sim, \
            open_rig({**_cfg(sim), "chamber": {"driver": "modbus", "url": sim.chamber_url,
                                               "map": str(stopping)}}, clock) as devices:
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        assert await asyncio.wait_for(runner.run(), 60) == "completed"
        assert runner.safe_report == {"chamber": "ok: setpoint 23 °C, controller stopped",
                                      "turntable": "ok: stopped, sent to (0, 0, 0)°"}
        chamber, table, sensor = await connect_rig(sim, clock)
        try:
            status = await chamber.read_status()
        finally:
            await chamber.close()
            await table.close()
            with contextlib.suppress(Exception):
                await sensor.close()
    assert status.setpoint_c == pytest.approx(SAFE_C, abs=0.05) and not status.running


@SQLITE_ONLY
async def test_abort_during_soak_ends_safe(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with twin(clock) as (sim, devices):
        task = asyncio.create_task(
            CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run())
        await until(lambda: state_of(sf, cid).cursor_phase == "soak")
        store.update_campaign(sf, cid, requested_action="abort")
        assert await asyncio.wait_for(task, 60) == "aborted"
        assert_safe(*await rig_state(sim, clock))


@SQLITE_ONLY
async def test_configuration_fault_fails_at_once_and_ends_safe(sf) -> None:  # type: ignore[no-untyped-def]
    """The second step's setpoint is beyond the controller's range: fail on the first try."""
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SPEC, "setpoints_c": [-40.0, 400.0]}, rig="lab")
    async with twin(clock) as (sim, devices):
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        assert await asyncio.wait_for(runner.run(), 60) == "failed"
        c = state_of(sf, cid)
        assert "chamber.set_setpoint" in c.error and "400" in c.error and "fix:" in c.error
        assert runner.guard.faults_retried == 0  # decided once, not retried
        assert_safe(*await rig_state(sim, clock))


@SQLITE_ONLY
async def test_unexpected_exception_from_a_device_layer_ends_safe(sf) -> None:  # type: ignore[no-untyped-def]
    """A non-DeviceFault (a decoder's UnicodeEncodeError) fails the campaign; rig still safe."""
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with twin(clock) as (sim, devices):
        acquire = devices.accelerometer.acquire
        calls = {"n": 0}

        async def flaky(n: int) -> Any:
            calls["n"] += 1
            if calls["n"] > 40:
                raise UnicodeEncodeError("ascii", "\xe9", 0, 1, "ordinal not in range(128)")
            return await acquire(n)

        devices.accelerometer.acquire = flaky  # type: ignore[method-assign]
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        assert await asyncio.wait_for(runner.run(), 60) == "failed"
        assert "UnicodeEncodeError" in state_of(sf, cid).error
        assert_safe(*await rig_state(sim, clock))


@SQLITE_ONLY
async def test_cancellation_ends_safe_and_leaves_the_campaign_to_recover(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with twin(clock) as (sim, devices):
        task = asyncio.create_task(
            CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run())
        await until(lambda: n_measured(sf, cid) >= 2)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await asyncio.wait_for(task, 60)
        assert state_of(sf, cid).state == "running"  # the next lease holder resumes it
        assert_safe(*await rig_state(sim, clock))


async def test_lost_lease_leaves_the_rig_to_its_new_holder(sf, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Another process takes the rig lease: the manager cancels the run and the engine sends
    the rig nothing more, park included (the new holder may be measuring: fencing.py)."""
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with start_sim_rig(clock, seed=5) as sim:

        @contextlib.asynccontextmanager
        async def the_twin(_cfg_row: Any, _clock: Any, **_kw: Any) -> AsyncIterator[RigDevices]:
            async with open_rig(_cfg(sim), clock) as devices:
                yield devices

        monkeypatch.setattr(manager_mod, "open_rig", the_twin)
        # The takeover below is written, not waited for, so the lease's length is not what
        # this test times. A 0.3 s lease (renewed every 0.1 s of wall time) expired under
        # load before the campaign had started, and the test then waited its 60 s for a
        # measurement that never came; so did a 3 s lease once in four runs of the suite on
        # a slower 2-core machine (four workers). 9 s (renewed every 3 s) bounds the wait for
        # the takeover to be seen at 3 s of wall time.
        mgr = CampaignManager(sf, clock_factory=lambda: clock, owner="me", lease_s=9.0)
        await mgr.run_once()
        await until(lambda: n_measured(sf, cid) >= 2)
        with sf() as s:  # the lease expired and another process took it
            s.execute(update(RigLease).where(RigLease.rig == "lab").values(owner="other"))
            s.commit()
        run = mgr._runs["lab"]
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.wait_for(run, 60)
        assert state_of(sf, cid).state == "running"
        n = n_measured(sf, cid)
        setpoint_c, _table = await rig_state(sim, clock)
        assert setpoint_c == pytest.approx(-40.0)  # not parked under the new holder
        assert n_measured(sf, cid) == n  # nothing written after the lease was lost
        await mgr.stop()


@SQLITE_ONLY
async def test_a_cancel_during_the_park_does_not_stop_it(sf) -> None:  # type: ignore[no-untyped-def]
    """The manager's cancel (lease lost) can land while the runner already parks: park anyway.

    Seen under load: the runner's own ``LeaseLost`` exit started the park, the
    manager's renewer cancelled the task mid-park, and the table stayed at 90°.
    """
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with twin(clock) as (sim, devices):
        stop = devices.turntable.stop
        parking = asyncio.Event()

        async def slow_stop() -> Any:
            parking.set()
            await clock.sleep(5.0)  # the cancel arrives here, before the table is sent home
            return await stop()

        task = asyncio.create_task(
            CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run())
        await until(lambda: n_measured(sf, cid) >= 2)
        devices.turntable.stop = slow_stop  # type: ignore[method-assign]
        store.update_campaign(sf, cid, requested_action="abort")
        await asyncio.wait_for(parking.wait(), 60)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):  # the cancel is kept, raised once parked
            await asyncio.wait_for(task, 60)
        assert_safe(*await rig_state(sim, clock))
