"""Device fencing: a process that lost (or cannot confirm) the rig lease sends the rig nothing.

The fakes' commands are recorded as they reach the devices (after the fence),
so "nothing sent" is read from what the devices saw, park included.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from engine_fakes import FakeRig, make_fake_rig
from engine_helpers import add_campaign, fake_calibrate
from sqlalchemy import select, update

from drivers.clock import VirtualClock
from service.db.models import Measurement, RigLease
from service.engine import store
from service.engine.fencing import fence_devices
from service.engine.manager import CampaignManager
from service.engine.runner import CampaignRunner

MUTATING = {"chamber": ("set_setpoint", "set_ramp_rate", "run", "stop"),
            "turntable": ("move_to", "stop"), "accelerometer": ("configure",)}


def record_commands(rig: FakeRig) -> list[str]:
    """Every rig-changing command the fake devices receive, in order, as ``device.command``."""
    sent: list[str] = []
    for name, commands in MUTATING.items():
        dev = getattr(rig, name)
        for cmd in commands:
            inner = getattr(dev, cmd)

            async def recorded(*args: Any, _inner: Any = inner, _label: str = f"{name}.{cmd}"
                               ) -> Any:
                sent.append(_label)
                return await _inner(*args)

            setattr(dev, cmd, recorded)
    return sent


def n_rows(sf: Any, cid: int) -> int:
    with sf() as s:
        return len(s.execute(select(Measurement.id).where(Measurement.campaign_id == cid)).all())


def take_over(sf: Any, rig: str = "sim") -> None:
    with sf() as s:  # proc-b took the rig over while proc-a was stalled
        s.execute(update(RigLease).where(RigLease.rig == rig).values(owner="proc-b"))
        s.commit()


async def run_until_taken_over(sf: Any, rows_first: int
                               ) -> tuple[FakeRig, list[str], CampaignRunner, asyncio.Task]:
    """proc-a runs a fenced campaign; proc-b takes the rig over once ``rows_first`` rows
    are stored. Returns the rig, its recorded commands, the runner and its task."""
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    sent = record_commands(rig)
    cid = add_campaign(sf)
    assert CampaignManager(sf, owner="proc-a", lease_s=3600)._claim("sim", cid)
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate,
                            fence=store.Fence("sim", "proc-a"))
    task = asyncio.create_task(runner.run())
    while n_rows(sf, cid) < rows_first:
        await asyncio.sleep(0.001)
    take_over(sf)
    return rig, sent, runner, task


async def test_a_runner_whose_lease_is_taken_sends_no_command_park_included(sf) -> None:  # type: ignore[no-untyped-def]
    rig, sent, runner, task = await run_until_taken_over(sf, 3)
    n_sent, setpoint_c, angles = len(sent), rig.physics.setpoint_c, rig.turntable.angles
    assert await asyncio.wait_for(task, 30) == "running"  # left to proc-b, not failed
    assert sent[n_sent:] == []  # not one command after the takeover, the park's included
    assert (rig.physics.setpoint_c, rig.turntable.angles) == (setpoint_c, angles)
    assert set(runner.safe_report.values()) == {"not sent: lease lost"}
    assert n_sent > 0 and "turntable.move_to" in sent  # it did drive the rig while it held it


async def test_a_cancel_after_the_lease_is_lost_parks_nothing(sf) -> None:  # type: ignore[no-untyped-def]
    """The manager's renewer cancels the run when it finds the lease taken: the shielded
    park then runs, and finds every command fenced."""
    _rig, sent, runner, task = await run_until_taken_over(sf, 2)
    n_sent = len(sent)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await asyncio.wait_for(task, 30)
    assert sent[n_sent:] == []
    assert set(runner.safe_report.values()) == {"not sent: lease lost"}


async def test_a_fenced_runner_that_keeps_its_lease_parks_as_always(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    sent = record_commands(rig)
    cid = add_campaign(sf, {"setpoints_c": [10.0], "soak_min": 30, "positions": "six",
                            "samples_per_position": 20})
    assert CampaignManager(sf, owner="proc-a", lease_s=3600)._claim("sim", cid)
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate,
                            fence=store.Fence("sim", "proc-a"))
    assert await asyncio.wait_for(runner.run(), 30) == "completed"
    assert sent[-3:] == ["chamber.set_setpoint", "turntable.stop", "turntable.move_to"]
    assert rig.physics.setpoint_c == 23.0 and rig.turntable.angles == (0.0, 0.0)
    assert runner.safe_report == {"chamber": "ok: setpoint 23 °C",
                                  "turntable": "ok: stopped, sent to (0, 0)°"}


async def test_a_lease_that_cannot_be_confirmed_sends_nothing() -> None:
    """The database does not answer: no command goes out, reads still do."""
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    sent = record_commands(rig)

    def unreachable() -> Any:
        raise ConnectionError("database at 10.0.0.9 does not answer")

    fenced = fence_devices(rig.devices, unreachable)
    with pytest.raises(store.LeaseLost, match=r"turntable\.move_to not sent: lease not "
                                              r"confirmed \(ConnectionError: database"):
        await fenced.turntable.move_to((90.0, 0.0))
    with pytest.raises(store.LeaseLost, match=r"chamber\.set_setpoint not sent"):
        await fenced.chamber.set_setpoint(60.0)
    assert sent == []
    status = await fenced.chamber.read_status()  # a read changes nothing: not fenced
    assert status.setpoint_c == 23.0 and fenced.turntable.n_axes == 2


async def test_a_stop_between_the_confirmation_and_the_command_sends_nothing() -> None:
    """Stopped after the database confirmed the lease, resumed after it ended (the stall
    benchmark's SIGSTOP right after a commit): the command is not sent."""
    import datetime as dt
    import time

    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    sent = record_commands(rig)

    def confirmed_then_stopped() -> dt.datetime:
        until = dt.datetime.now(dt.UTC) + dt.timedelta(seconds=0.05)  # what the row said
        time.sleep(0.08)  # the process is stopped here, past the lease's end
        return until

    fenced = fence_devices(rig.devices, confirmed_then_stopped)
    with pytest.raises(store.LeaseLost, match=r"turntable\.move_to not sent: the lease ended "
                                              r"at .* while it was being confirmed"):
        await fenced.turntable.move_to((90.0, 0.0))
    assert sent == []
