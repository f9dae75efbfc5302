"""Pause is not soak: time paused mid-soak never counts towards the soak or its cap."""

from __future__ import annotations

import asyncio

from engine_fakes import make_fake_rig
from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate
from test_control import wait_for
from test_runner import assert_complete_once, campaign

from drivers.clock import VirtualClock
from service.engine import store
from service.engine.runner import CampaignRunner

MAX_SOAK_S = 2 * SMALL_SPEC["soak_min"] * 60.0  # the spec's default cap: twice soak_min
SPEC = {**SMALL_SPEC, "on_max_soak": "fail"}


async def test_a_pause_longer_than_max_soak_mid_soak_neither_fails_nor_caps_the_soak(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, SPEC)
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate)
    task = asyncio.create_task(runner.run())
    await wait_for(lambda: campaign(sf, cid).cursor_phase == "soak")
    store.update_campaign(sf, cid, requested_action="pause")
    await wait_for(lambda: campaign(sf, cid).state == "paused")
    assert campaign(sf, cid).cursor_phase == "soak" and campaign(sf, cid).cursor_step == 0
    await clock.sleep(2.5 * MAX_SOAK_S)  # paused for longer than the soak may last
    store.update_campaign(sf, cid, requested_action="resume")
    assert await asyncio.wait_for(task, 30) == "completed", campaign(sf, cid).error
    assert_complete_once(sf, cid)
    first = next(e for e in campaign(sf, cid).steps_log if e["step"] == 0)
    assert first["held_s"] >= 2.5 * MAX_SOAK_S  # the pause was inside this soak
    assert not first["max_soak_reached"] and first["reason"] != "max_soak_reached"
    # a decision on the die's probes (stability.decide), not the cap
    assert first["reason"] in ("die_flat", "die_predicted_within_tol")
    assert first["predicted_offset_c"] is not None
    assert first["soak_s"] < MAX_SOAK_S  # soaked time, the pause not included
    # the ETA learned the soak's own duration, not the pause's
    assert runner.eta.soak_times_s[0] < MAX_SOAK_S
