"""Pause, resume and abort through ``campaign.requested_action`` (as the API writes it)."""

from __future__ import annotations

import asyncio

import pytest
from engine_fakes import make_fake_rig
from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate
from test_runner import assert_complete_once, campaign, measurements

from calibration.campaign_spec import MAX_SETTLE_S
from drivers.clock import VirtualClock
from service.engine import store
from service.engine.runner import ABORT_CHECK_S, CampaignRunner
from service.engine.states import IllegalTransition, check_action


async def wait_for(pred, timeout_s: float = 20.0) -> None:  # type: ignore[no-untyped-def]
    async def loop() -> None:
        while not pred():
            await asyncio.sleep(0.001)

    await asyncio.wait_for(loop(), timeout_s)


async def test_pause_holds_safe_then_resume_completes(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    task = asyncio.create_task(
        CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate).run())
    await wait_for(lambda: len(measurements(sf, cid)) >= 3)
    store.update_campaign(sf, cid, requested_action="pause")
    await wait_for(lambda: campaign(sf, cid).state == "paused")
    n_paused = len(measurements(sf, cid))
    t_paused = clock.now()
    await clock.sleep(3 * 3600.0)  # hours pass while paused: nothing is measured
    assert campaign(sf, cid).state == "paused"
    assert len(measurements(sf, cid)) == n_paused
    assert rig.turntable.stops >= 1  # table at rest
    assert rig.physics.setpoint_c == SMALL_SPEC["setpoints_c"][0]  # chamber holds its setpoint
    assert clock.now() - t_paused >= 3 * 3600.0
    store.update_campaign(sf, cid, requested_action="resume")
    assert await asyncio.wait_for(task, 30) == "completed"
    assert campaign(sf, cid).requested_action is None
    assert_complete_once(sf, cid)


@pytest.mark.parametrize("when", ["soak", "positions", "paused"])
async def test_abort_leaves_rig_safe(sf, when: str) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    task = asyncio.create_task(
        CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate).run())
    if when == "soak":
        await wait_for(lambda: campaign(sf, cid).cursor_phase == "soak")
    else:
        await wait_for(lambda: len(measurements(sf, cid)) >= 2)
    if when == "paused":
        store.update_campaign(sf, cid, requested_action="pause")
        await wait_for(lambda: campaign(sf, cid).state == "paused")
    store.update_campaign(sf, cid, requested_action="abort")
    assert await asyncio.wait_for(task, 30) == "aborted"
    c = campaign(sf, cid)
    assert c.state == "aborted" and c.finished_at is not None and c.calibration_id is None
    assert rig.physics.setpoint_c == 23.0  # safe temperature
    assert rig.turntable.angles == (0.0, 0.0)  # table home


async def test_finished_campaign_is_not_rerun(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [20.0]}, state="aborted")
    assert await CampaignRunner(sf, cid, rig.devices, clock).run() == "aborted"
    assert rig.accelerometer.acquisitions == 0


def test_illegal_transitions_raise() -> None:
    with pytest.raises(IllegalTransition):
        check_action("resume", "completed")
    with pytest.raises(IllegalTransition):
        check_action("pause", "paused")
    check_action("abort", "paused")


def test_runner_refuses_transitions_outside_the_table(sf) -> None:
    cid = add_campaign(sf, state="completed")
    assert store.transition(sf, cid, "running") is False
    assert campaign(sf, cid).state == "completed"


async def test_abort_is_honoured_during_a_very_long_settle(sf) -> None:
    """The longest settle a spec may ask for: the abort must not wait for it (nor hold the rig).

    The spec bounds settle_s (service/engine/spec.py MAX_SETTLE_S; 1e9 is a 422 at the door),
    so the engine's own abort checks are tested at the bound, 10 abort-check periods long.
    """
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    assert MAX_SETTLE_S >= 10 * ABORT_CHECK_S
    cid = add_campaign(sf, {**SMALL_SPEC, "settle_s": MAX_SETTLE_S})
    task = asyncio.create_task(
        CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate).run())
    await wait_for(lambda: campaign(sf, cid).cursor_phase == "positions")
    t_asked = clock.now()
    store.update_campaign(sf, cid, requested_action="abort")
    assert await asyncio.wait_for(task, 10) == "aborted"
    # Honoured within the move in progress plus one abort-check period of the settle (60 s),
    # not after the whole settle.
    assert clock.now() - t_asked <= 2 * ABORT_CHECK_S
    assert rig.physics.setpoint_c == 23.0


async def test_an_unusable_spec_fails_through_the_table_without_touching_the_rig(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, {**SMALL_SPEC, "on_max_soak": "explode"})
    assert await CampaignRunner(sf, cid, rig.devices, clock).run() == "failed"
    c = campaign(sf, cid)
    assert c.state == "failed" and "on_max_soak" in c.error and c.finished_at is not None
    assert rig.accelerometer.acquisitions == 0 and rig.physics.setpoint_c == 23.0
    assert rig.turntable.stops == 0  # never touched: no safe-state commands either
