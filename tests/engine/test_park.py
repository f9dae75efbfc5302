"""The rig parks device by device (service/engine/park.py), and the fence holds per write.

What a person reads is the report: one line per device. These tests hang,
fail and fence single devices and read that report, the twin's registers and
the clock.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import pytest
from engine_fakes import make_fake_rig

from drivers.clock import VirtualClock
from drivers.faults import DeviceTimeout
from drivers.manual_table import ManualTurntable
from service.engine import store
from service.engine.fencing import fence_devices
from service.engine.park import PARK_ATTEMPTS, park_rig, parked
from service.engine.rigs import RigDevices
from simulators.rig import connect_rig, start_sim_rig


async def test_a_hung_chamber_does_not_keep_the_table_from_parking() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    hung = asyncio.Event()  # never set: the chamber never answers
    tries = {"n": 0}

    async def hang(setpoint_c: float | None = None) -> str:
        tries["n"] += 1
        await hung.wait()
        return "never"

    rig.chamber.park = hang  # type: ignore[method-assign]
    rig.turntable.angles = rig.turntable.physical_angles = (90.0, 45.0)
    report = await asyncio.wait_for(park_rig(rig.devices, clock, timeout_s=0.05), 10)
    assert report == {"chamber": f"failed after {PARK_ATTEMPTS} tries: no answer within 0.05 s",
                      "turntable": "ok: stopped, sent to (0, 0)°"}
    assert rig.turntable.angles == (0.0, 0.0) and rig.turntable.stops == 1
    # sent home at once (clock 0 + its slew), not after the chamber's tries ran out
    assert rig.turntable.arrive_s == rig.turntable.SLEW_S
    assert tries["n"] == PARK_ATTEMPTS
    assert clock.now() == pytest.approx(1.0 + 2.0)  # back-off on the clock between tries


async def test_a_device_that_fails_twice_is_parked_at_its_third_try() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    rig.physics.setpoint_c = -40.0
    park = rig.chamber.park
    tries = {"n": 0}

    async def flaky(setpoint_c: float | None = None) -> str:
        tries["n"] += 1
        if tries["n"] < 3:
            raise DeviceTimeout("chamber", "no reply (injected)")
        return await park(setpoint_c)

    rig.chamber.park = flaky  # type: ignore[method-assign]
    report = await park_rig(rig.devices, clock, safe_c=15.0)
    assert report["chamber"] == "ok: setpoint 15 °C"  # the campaign's safe_c overrides
    assert rig.physics.setpoint_c == 15.0 and tries["n"] == 3
    assert all(parked(line) for line in report.values())


async def test_a_device_that_never_parks_is_reported_with_its_last_error() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)

    async def broken() -> str:
        raise DeviceTimeout("turntable", "no reply within 1.0 s")

    rig.turntable.park = broken  # type: ignore[method-assign]
    report = await park_rig(rig.devices, clock)
    assert report == {"chamber": "ok: setpoint 23 °C",
                      "turntable": "failed after 3 tries: DeviceTimeout: turntable: "
                                   "no reply within 1.0 s"}
    assert not parked(report["turntable"])


async def test_a_lost_lease_parks_nothing_and_is_not_retried() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    rig.physics.setpoint_c = -40.0
    asked = {"n": 0}

    def taken() -> Any:
        asked["n"] += 1
        raise store.LeaseLost("rig 'sim': lease no longer held by proc-a")

    report = await park_rig(fence_devices(rig.devices, taken), clock)
    assert report == {"chamber": "not sent: lease lost", "turntable": "not sent: lease lost"}
    assert asked["n"] == 2  # once per device: a lost lease is not tried again
    assert rig.physics.setpoint_c == -40.0 and rig.turntable.moves == 0
    assert clock.now() == 0.0  # no back-off waited


async def test_a_hand_placed_fixture_has_nothing_to_move_and_asks_nothing() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)

    class Board:
        published: list[Any] = []

        def publish(self, ref_g: Any, reason: str | None = None) -> None:
            self.published.append(ref_g)

    board = Board()
    devices = RigDevices(rig.chamber, ManualTurntable(board), rig.accelerometer,
                         rig.devices.angles_for)
    report = await park_rig(devices, clock)
    assert report["turntable"] == ("ok: nothing to move (hand-placed fixture: the sensor "
                                   "stays where it was placed)")
    assert board.published == []  # no last "home" request left for the operator


@contextlib.asynccontextmanager
async def twin(clock: VirtualClock, **kw: Any) -> Any:
    async with start_sim_rig(clock, seed=2, modbus_in_memory=True, **kw) as sim:
        chamber, table, sensor = await connect_rig(sim, clock)
        try:
            yield sim, RigDevices(chamber, table, sensor, lambda ref: (0.0, 0.0, 0.0))
        finally:
            await chamber.close()
            await table.close()
            with contextlib.suppress(Exception):
                await sensor.close()


async def test_the_chamber_parks_at_its_range_edge_when_asked_beyond_it() -> None:
    clock = VirtualClock()
    async with twin(clock) as (_sim, devices):
        lo_c, hi_c = devices.chamber.range_c
        report = await park_rig(devices, clock, safe_c=hi_c + 50.0)
        assert report["chamber"] == (f"ok: setpoint {hi_c:g} °C (the range's edge; "
                                     f"{hi_c + 50.0:g} °C asked)")
        assert (await devices.chamber.read_status()).setpoint_c == pytest.approx(hi_c)


async def test_a_lease_lost_between_the_targets_and_the_move_command_moves_nothing() -> None:
    """A table move is two write requests (targets 200–205, command 210). The fence is
    confirmed before each: a lease lost between them leaves the command unsent, and a
    stale target without its command moves nothing."""
    clock = VirtualClock()
    async with twin(clock) as (sim, devices):
        confirmations: list[str] = []

        def confirm() -> Any:
            confirmations.append("asked")
            if len(confirmations) > 2:  # the command-level check, then the targets' write
                raise store.LeaseLost("rig 'sim': lease no longer held by proc-a")
            return None

        fenced = fence_devices(devices, confirm)
        with pytest.raises(store.LeaseLost,
                           match=r"^turntable write of register 210 not sent: rig 'sim'"):
            await fenced.turntable.move_to((90.0, 0.0, 0.0))
        await clock.sleep(30.0)
        status = await devices.turntable.read_status()  # reads are not fenced
        assert status.angles_deg == pytest.approx((0.0, 0.0, 0.0)) and not status.moving
        assert sim.table.true_angles_deg() == pytest.approx((0.0, 0.0, 0.0))
        # The same lease lost before a park: not one write goes out, the report says so.
        setpoint_before_c = (await devices.chamber.read_status()).setpoint_c
        report = await park_rig(fenced, clock)
        assert report == {"chamber": "not sent: lease lost", "turntable": "not sent: lease lost"}
        assert (await devices.chamber.read_status()).setpoint_c == setpoint_before_c
