"""Suspenders on the engine, through the twin: chamber alarm, chamber out of band, table.

Each condition is caused in the twin's physics (a door opened: the air jumps;
the table's in-position bit never comes), and the campaign must say why it
holds, take no reading meanwhile, and resume or fail by its policy.
"""

from __future__ import annotations

import asyncio
from collections import Counter
from typing import Any

import pytest
from engine_helpers import SMALL_SPEC, SQLITE_ONLY, add_campaign, fake_calibrate
from sqlalchemy import select
from test_safe_state import assert_safe, n_measured, rig_state, twin, until

from calibration.campaign_plan import PollSoak, SetChamber, WaitStable
from drivers.clock import VirtualClock
from service.db.models import Measurement
from service.engine import store
from service.engine.runner import CampaignRunner

SPEC: dict[str, Any] = {**SMALL_SPEC, "setpoints_c": [-10.0, 30.0], "positions": "six",
                        "samples_per_position": 20}


def keys(sf: Any, cid: int) -> Counter:
    with sf() as s:
        rows = s.execute(select(Measurement.step, Measurement.position)
                         .where(Measurement.campaign_id == cid)).all()
    return Counter((int(a), int(b)) for a, b in rows)


@SQLITE_ONLY
async def test_chamber_alarm_twice_suspends_resoaks_and_completes(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    reasons: list[str] = []
    async with twin(clock) as (sim, devices):
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        seen: list[Any] = []
        runner.subscribe(lambda msg, _t0, _t1: seen.append(msg))
        task = asyncio.create_task(runner.run())
        for n in (2, 8):  # open the door twice: the air jumps 12 °C above the setpoint
            await until(lambda n=n: n_measured(sf, cid) >= n)
            sim.chamber.advance_to()
            sim.chamber.air_c += 12.0
            await until(lambda: store.load_campaign(sf, cid).suspended_reason is not None
                        or task.done())
            reasons.append(store.load_campaign(sf, cid).suspended_reason or "")
        assert await asyncio.wait_for(task, 60) == "completed"
        assert_safe(*await rig_state(sim, clock))
    # the twin serves the Eurotherm 3216 map, whose AL1 the twin configures as deviation high
    assert all(r.startswith("chamber_alarm: chamber alarm: alarm_1") for r in reasons), reasons
    holds = [e["suspender"] for e in runner.suspension_log]
    assert holds.count("chamber_alarm") == 2, runner.suspension_log
    # A suspension is a rewind: each hold is followed by the plan's own re-ramp and re-soak
    # of the step it interrupted, which every subscriber sees.
    resoaks = [(m.step, m.resumed) for m in seen if isinstance(m, WaitStable)]
    assert resoaks == [(0, False), (0, True), (1, False), (1, True)], resoaks
    counts = keys(sf, cid)
    assert set(counts) == {(s, p) for s in range(2) for p in range(6)}
    assert max(counts.values()) == 1
    c = store.load_campaign(sf, cid)
    assert c.suspended_reason is None
    # No stored reading was taken while the air was off: the die stayed near its setpoint.
    with sf() as s:
        for m in s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars():
            assert abs(m.chamber_c - SPEC["setpoints_c"][m.step]) < 2.0


@SQLITE_ONLY
@pytest.mark.parametrize(("band_c", "holds"), [(None, ["chamber_band"]), (5.0, [])])
async def test_chamber_out_of_band_without_alarm_suspends(  # type: ignore[no-untyped-def]
        sf, band_c: float | None, holds: list[str]) -> None:
    """3.5 °C off (below the controller's 5 °C alarm) is too far for a reading by default;
    ``chamber_band_c`` 5 (a chamber that swings wider at −40 °C) lets it pass."""
    clock = VirtualClock(idle_wall_s=0.0003)
    spec = SPEC if band_c is None else {**SPEC, "chamber_band_c": band_c}
    cid = add_campaign(sf, spec, rig="lab")
    async with twin(clock) as (sim, devices):
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        task = asyncio.create_task(runner.run())
        await until(lambda: n_measured(sf, cid) >= 3)
        sim.chamber.advance_to()
        sim.chamber.air_c += 3.5
        assert await asyncio.wait_for(task, 60) == "completed"
    assert [e["suspender"] for e in runner.suspension_log] == holds
    assert max(keys(sf, cid).values()) == 1 and len(keys(sf, cid)) == 12


@SQLITE_ONLY
async def test_table_never_in_position_suspends_then_fails_safe(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SPEC, "suspend_limit_s": 600.0, "move_timeout_s": 60.0}, rig="lab")
    async with twin(clock) as (sim, devices):
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        task = asyncio.create_task(runner.run())
        await until(lambda: n_measured(sf, cid) >= 2)
        sim.faults.table.never_in_position = True
        await until(lambda: (store.load_campaign(sf, cid).suspended_reason or "").startswith(
            "turntable_position") or task.done())
        assert not task.done()
        assert "not in position" in store.load_campaign(sf, cid).suspended_reason
        assert await asyncio.wait_for(task, 60) == "failed"
        assert "600 s of real time" in store.load_campaign(sf, cid).error
        sim.faults.table.never_in_position = False
        assert_safe(*await rig_state(sim, clock))


@SQLITE_ONLY
async def test_a_disturbed_soak_is_a_hold_then_a_fresh_soak(sf) -> None:  # type: ignore[no-untyped-def]
    # The door opened mid-soak, before any position of the step was stored: after the hold
    # the plan replays the step from what is stored (nothing), so the soak starts afresh
    # (not the short re-check of a step with positions stored), and the step has one log.
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with twin(clock) as (sim, devices):
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
        seen: list[Any] = []
        runner.subscribe(lambda msg, _t0, _t1: seen.append(msg))
        task = asyncio.create_task(runner.run())
        await until(lambda: any(isinstance(m, PollSoak) for m in seen))
        sim.chamber.advance_to()
        sim.chamber.air_c += 12.0
        assert await asyncio.wait_for(task, 60) == "completed"
    assert [e["suspender"] for e in runner.suspension_log] == ["chamber_alarm"]
    resoaks = [(m.step, m.resumed) for m in seen if isinstance(m, WaitStable)]
    assert resoaks == [(0, False), (1, False)], resoaks  # the disturbed one never ended
    ramps = [m.step for m in seen if isinstance(m, SetChamber)]
    assert ramps == [0, 0, 1]  # the replay commands the step's setpoint again
    log = store.load_campaign(sf, cid).steps_log
    assert [e["step"] for e in log] == [0, 1] and not log[0]["resumed"]
    assert max(keys(sf, cid).values()) == 1 and len(keys(sf, cid)) == 12
