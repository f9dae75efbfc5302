"""Campaigns over the wire on a drive per axis (the Leadshine RS485 profile on the twin),
and on a 1-axis motorised stage whose second axis the operator sets by hand, the test
confirming each hand placement over REST as an operator would (docs/manual-fixtures.md)."""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
import numpy as np
import pytest
from sqlalchemy import select

from drivers.clock import VirtualClock
from drivers.manual_table import HandAxisTurntable
from service.api.app import create_app
from service.api.auth import create_token
from service.config import Settings
from service.db.models import Campaign, Measurement
from service.engine.rigs import open_rig, rig_config_errors
from service.engine.runner import CampaignRunner
from simulators.rig import start_sim_rig

from engine_helpers import (  # isort: skip
    POSE_COLUMNS, SMALL_SPEC, SQLITE_ONLY, add_campaign, assert_poses_give_references,
    fake_calibrate)

HAND_SPEC: dict[str, Any] = {"setpoints_c": [5.0, 20.0], "soak_min": 10, "positions": "six",
                             "samples_per_position": 30, "move_timeout_s": 3600.0}


def _angle_deg(m: Any) -> float:
    """Angle between an averaged reading and its scheduled reference (scale errors aside)."""
    a, r = np.array([m.ax, m.ay, m.az]), np.array([m.ref_x, m.ref_y, m.ref_z])
    return float(np.degrees(np.arccos(np.clip(a @ r / np.linalg.norm(a) / np.linalg.norm(r),
                                              -1.0, 1.0))))


def _config(sim: Any, **table: Any) -> dict[str, Any]:
    return {"name": "lab",
            "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": "eurotherm3216",
                        "range_c": [-70, 180]},
            "turntable": {"url": sim.table_url, "map": "leadshine-rs485-pr", **table},
            "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}


@SQLITE_ONLY
async def test_a_campaign_runs_on_a_drive_per_axis_over_the_wire(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [10.0, 30.0],
                            "samples_per_position": 20}, rig="lab")
    async with start_sim_rig(clock, seed=5, table_map="leadshine-rs485-pr") as sim:
        devices_cm = open_rig(_config(sim), clock)
        async with devices_cm as devices:
            assert devices.turntable.n_axes == 2
            state = await asyncio.wait_for(
                CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run(), 120.0)
    with sf() as s:
        assert state == "completed", s.get(Campaign, cid).error
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
    assert sorted(m.position for m in rows) == sorted(list(range(6)) * 2)
    for m in rows:  # each reading is where the schedule asked: the drives really moved
        assert _angle_deg(m) < 3.0


def test_rig_configs_for_drives_and_hand_axes_are_checked_by_key() -> None:
    chamber = {"driver": "modbus", "url": "tcp://h:502", "map": "eurotherm3216"}
    sensors = [{"url": "/dev/ttyUSB0"}]
    table = {"url": "tcp://h:503", "map": "leadshine-rs485-pr"}

    def errs(**t: Any) -> dict[str, str]:
        return dict(rig_config_errors(chamber, {**table, **t}, sensors))

    assert errs() == {}
    assert errs(unit_ids=[3, 4]) == {}
    assert "distinct" in errs(unit_ids=[3, 3])["turntable.unit_ids"]
    assert "turntable.hand_axis" in errs(axes=1)["turntable.axes"]
    assert errs(axes=1, hand_axis={"steps_deg": [0, 90, 180, 270]}) == {}
    assert "set turntable.axes = 1" in errs(hand_axis={})["turntable.hand_axis"]
    typo = errs(axes=1, hand_axis={"step_deg": [0]})
    assert "unknown key" in typo["turntable.hand_axis.step_deg"]
    on_bus = {**table, "url": "tcp://h:502"}  # drives on the chamber's bus (unit 1)
    assert "the chamber answers unit 1 at the same url, and so would the drive of axis 0" in \
        dict(rig_config_errors(chamber, on_bus, sensors))["turntable.map"]
    assert rig_config_errors(chamber, {**on_bus, "unit_ids": [2, 3]}, sensors) == []
    assert "use device_id" in dict(rig_config_errors(
        chamber, {"url": "tcp://h:503", "map": "soakcal-table", "unit_ids": [1, 2, 3]},
        sensors))["turntable.unit_ids"]


async def _operator(client: httpx.AsyncClient, headers: dict[str, str], clock: VirtualClock,
                    sim: Any, cid: int, wrong_first: bool = False) -> list[dict[str, Any]]:
    """Read each pending request, turn the twin's hand axis to the angle asked, confirm;
    with ``wrong_first`` the first one a quarter turn off."""
    seen: set[int] = set()
    confirmed: list[dict[str, Any]] = []
    while True:
        body = (await client.get(f"/api/v1/campaigns/{cid}/placement", headers=headers)).json()
        if body["campaign_state"] != "running":
            return confirmed
        req = body["request"]
        if req and req["state"] == "pending" and req["seq"] not in seen:
            seen.add(req["seq"])
            words = req["instruction"].split()
            assert words[:5] == ["turn", "the", "hand", "axis", "to"], req["instruction"]
            hand = float(words[5].rstrip("°")) + (90.0 if wrong_first and not confirmed else 0.0)
            sim.table.move_axis(1, hand)  # the operator's hands
            while not sim.table.axis_in_position(1):  # turned and locked, then confirmed
                await clock.sleep(1.0)
            r = await client.post(f"/api/v1/campaigns/{cid}/placement", headers=headers,
                                  json={"position": req["position"]})
            assert r.status_code in (200, 409), r.text
            if r.status_code == 200:
                confirmed.append(req)
        await clock.sleep(5.0)


@SQLITE_ONLY
@pytest.mark.parametrize("wrong_first", [False, True])
async def test_a_one_axis_stage_with_a_hand_axis_completes_with_the_operator(
        sf, migrated_db_url: str, wrong_first: bool) -> None:  # type: ignore[no-untyped-def]
    spec = {**HAND_SPEC, "setpoints_c": [20.0]} if wrong_first else HAND_SPEC
    cid = add_campaign(sf, spec=spec, rig="lab")
    app = create_app(Settings(database_url=migrated_db_url, run_engine=False,
                              run_scheduler=False, migrate=False))
    with sf() as s:
        token = create_token(s, "operator")
        s.commit()
    headers = {"Authorization": f"Bearer {token}"}
    clock = VirtualClock(idle_wall_s=0.002)
    # The twin's two drives: the rig uses unit 1 (the motor); axis 1 is the operator's.
    async with start_sim_rig(clock, seed=7, table_map="leadshine-rs485-pr") as sim:
        rig = _config(sim, axes=1, hand_axis={"steps_deg": [0, 90, 180, 270]})
        assert rig_config_errors(rig["chamber"], rig["turntable"], rig["sensors"]) == []
        async with open_rig(rig, clock, placement_sf=sf) as devices:
            assert isinstance(devices.turntable, HandAxisTurntable)
            runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
            async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app),
                                         base_url="http://t") as client:
                op = asyncio.create_task(_operator(client, headers, clock, sim, cid,
                                                   wrong_first))
                state = await asyncio.wait_for(runner.run(), 120.0)
                confirmed = await asyncio.wait_for(op, 30.0)
    with sf() as s:
        assert state == "completed", s.get(Campaign, cid).error
    with sf() as s:
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
    assert sorted(m.position for m in rows) == sorted(list(range(6)) * len(spec["setpoints_c"]))
    for m in rows:  # the motor and the operator together put each reference along gravity
        assert _angle_deg(m) < 3.0
    # The pose is known from the motor's and the hand axis' angles: recorded, and the six
    # directions lie on the hand steps, so each is exactly its reference's.
    assert_poses_give_references([{c: getattr(m, c) for c in (*POSE_COLUMNS, "ref_x", "ref_y",
                                                               "ref_z")} for m in rows])
    # Only hand-angle changes were asked (six positions need hand 0, ±90, 180; the motor
    # does ±y on its own), each once per step at most.
    # The operator was asked only for the hand axis, at the indexer's steps, at most once
    # per position and step (a motor-only move such as +z → ±y asks nothing when the hand
    # stays), and every placement passed its check.
    asked = [float(c["instruction"].split()[5].rstrip("°")) for c in confirmed]
    assert set(asked) <= {0.0, 90.0, -90.0, 180.0}
    rejections = devices.turntable.rejections
    if wrong_first:  # a quarter turn off: re-asked with the reason, then placed right
        assert len(rejections) == 1 and "from the asked direction" in rejections[0]
        assert confirmed[1]["reason"] == rejections[0]
        assert confirmed[1]["instruction"] == confirmed[0]["instruction"]
    else:
        assert rejections == []
    assert 4 <= len(confirmed) - len(rejections) <= 6 * len(spec["setpoints_c"])


@SQLITE_ONLY
async def test_a_schedule_the_hand_steps_cannot_reach_is_refused_with_why(sf) -> None:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, spec={**HAND_SPEC, "positions": "cube14"}, rig="lab")
    clock = VirtualClock(idle_wall_s=0.0003)
    async with start_sim_rig(clock, seed=7, table_map="leadshine-rs485-pr") as sim:
        rig = _config(sim, axes=1, hand_axis={"steps_deg": [0, 90, 180, 270]})
        async with open_rig(rig, clock, placement_sf=sf) as devices:
            state = await asyncio.wait_for(
                CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run(), 60.0)
    assert state == "failed"
    with sf() as s:
        error = s.get(Campaign, cid).error
    assert "the hand axis stops only at 0°, 90°, 180°, 270°" in error, error
    assert "with hand -45.0°" in error or "with hand 135.0°" in error, error
