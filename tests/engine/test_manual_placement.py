"""Hand-placed fixtures: the placement check, the request board, and a twin campaign
where the test plays the operator through the REST endpoint (docs/manual-fixtures.md)."""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
import numpy as np
import pytest
from engine_helpers import add_campaign, fake_calibrate
from sqlalchemy import select, update

from calibration.placement import check_placement, instruction_for, sketch_for
from drivers.clock import VirtualClock
from drivers.geometry import angles_for_reference
from drivers.manual_table import ManualTurntable
from service.api.app import create_app
from service.api.auth import create_token
from service.config import Settings
from service.db.models import Calibration, Campaign, Measurement, Rig
from service.engine.placement import PlacementBoard, hand_placed_calibrate, manual_devices
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner

NOISE_G = 0.2e-3


# --- pure functions -------------------------------------------------------------------
def test_instruction_names_the_up_face_and_a_heading() -> None:
    assert instruction_for(np.array([0, 0, 1.0])).startswith("face +z up, x towards the door")
    assert instruction_for(np.array([-1.0, 0, 0])).startswith("face -x up")
    oblique = instruction_for(np.array([1.0, 1.0, 1.0]) / np.sqrt(3))
    assert "x +35°" in oblique and "z +35°" in oblique
    assert "+y up" in sketch_for(np.array([0, 1.0, 0]))


def test_check_accepts_a_static_sensor_a_few_degrees_off() -> None:
    tilt = np.radians(5.0)
    seen = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    check = check_placement(seen, np.full(3, NOISE_G), np.array([0, 0, 1.0]), NOISE_G)
    assert check.ok and check.static and 4.9 < check.angle_deg < 5.1


def test_check_rejects_the_wrong_face_with_what_to_do() -> None:
    check = check_placement(np.array([-1.0, 0, 0]), np.full(3, NOISE_G),
                            np.array([1.0, 0, 0]), NOISE_G)
    assert not check.ok
    assert check.reason.startswith("x looks down, not up")
    assert "turn the cube" in check.reason


def test_check_rejects_a_moving_sensor_even_when_pointing_right() -> None:
    check = check_placement(np.array([0, 0, 1.0]), np.array([5e-3, 1e-3, 1e-3]),
                            np.array([0, 0, 1.0]), NOISE_G)
    assert not check.ok and not check.static and "moving" in check.reason


def test_check_rejects_a_tilt_beyond_the_limit() -> None:
    tilt = np.radians(25.0)
    seen = np.array([0.0, np.sin(tilt), np.cos(tilt)])
    check = check_placement(seen, np.full(3, NOISE_G), np.array([0, 0, 1.0]), NOISE_G)
    assert not check.ok and "seat the fixture flat" in check.reason


# --- the twin, operator played over REST ----------------------------------------------
MANUAL_SPEC: dict[str, Any] = {
    "setpoints_c": [5.0, 20.0, 35.0, 50.0], "soak_min": 10, "positions": "six",
    "samples_per_position": 50, "move_timeout_s": 3600.0,
}


async def _operator(client: httpx.AsyncClient, headers: dict[str, str], clock: VirtualClock,
                    sim_table: Any, cid: int, wrong_first: bool) -> list[dict[str, Any]]:
    """Read each pending request, turn the twin's table there, confirm; the first one wrong."""
    seen: set[int] = set()
    confirmed: list[dict[str, Any]] = []
    while True:
        body = (await client.get(f"/api/v1/campaigns/{cid}/placement", headers=headers)).json()
        if body["campaign_state"] != "running":
            return confirmed
        req = body["request"]
        if req and req["state"] == "pending" and req["seq"] not in seen:
            seen.add(req["seq"])
            ref = np.asarray(req["ref_g"])
            if wrong_first and not confirmed:
                ref = -ref  # the cube upside down
            await sim_table.move_to(angles_for_reference(ref))
            while not (await sim_table.read_status()).in_position:
                await clock.sleep(1.0)
            r = await client.post(f"/api/v1/campaigns/{cid}/placement", headers=headers,
                                  json={"position": req["position"]})
            if r.status_code == 200:
                confirmed.append(req)
            else:  # only once the campaign ended between the read and the confirmation
                assert r.status_code == 409, r.text
        await clock.sleep(5.0)


@pytest.mark.parametrize("wrong_first", [False, True])
async def test_manual_campaign_on_the_twin_completes_with_the_operator_over_rest(
        sf, migrated_db_url: str, wrong_first: bool) -> None:
    # The rejected first placement happens at step 0; with the fake fit two steps show it as
    # well as four (the real, cubic fit needs the four).
    spec = {**MANUAL_SPEC, "setpoints_c": [5.0, 20.0]} if wrong_first else MANUAL_SPEC
    cid = add_campaign(sf, spec=spec, rig="bench")
    app = create_app(Settings(database_url=migrated_db_url, run_engine=False,
                              run_scheduler=False, migrate=False))
    with sf() as s:
        token = create_token(s, "operator")
        s.commit()
    headers = {"Authorization": f"Bearer {token}"}
    clock = VirtualClock(idle_wall_s=0.002)
    rig = {"name": "bench", "chamber": {"driver": "sim"}, "turntable": {"driver": "manual"}}
    async with open_rig({**rig, "turntable": {}}, clock, seed=3) as twin:
        sim_table = twin.turntable  # the twin's table: the operator's hands
        devices = manual_devices(rig, twin, sf)
        assert isinstance(devices.turntable, ManualTurntable)
        # The real fit once (hand-placed: ref_tol_deg on every row), the fake one otherwise.
        calibrate = fake_calibrate if wrong_first else hand_placed_calibrate()
        runner = CampaignRunner(sf, cid, devices, clock, calibrate=calibrate)
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://t") as client:
            op = asyncio.create_task(_operator(client, headers, clock, sim_table, cid,
                                               wrong_first))
            state = await asyncio.wait_for(runner.run(), 120.0)
            confirmed = await asyncio.wait_for(op, 30.0)
    assert state == "completed"
    with sf() as s:
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
        assert s.get(Campaign, cid).state == "completed"
    assert sorted(m.position for m in rows) == sorted(list(range(6)) * len(spec["setpoints_c"]))
    for m in rows:  # each averaged reading is where the schedule asked: the operator placed it
        assert np.dot([m.ax, m.ay, m.az], [m.ref_x, m.ref_y, m.ref_z]) > 0.95
        # asked for a direction only: the heading about gravity is the operator's, no pose
        assert (m.pose_qw, m.pose_qx, m.pose_qy, m.pose_qz) == (None,) * 4
    rejections = devices.turntable.rejections
    if wrong_first:
        assert len(rejections) == 1 and "looks down, not up" in rejections[0]
        assert confirmed[0]["position"] == confirmed[1]["position"]  # the same one, re-asked
        assert confirmed[1]["reason"] == rejections[0]
    else:
        assert rejections == []
    assert len({c["position"] for c in confirmed}) == 6
    if not wrong_first:
        with sf() as s:
            cal = s.get(Calibration, s.get(Campaign, cid).calibration_id)
            assert cal.provenance["ref_tol_deg"] == 2.0 and cal.rmse_ug > 0
            assert "hand-placed references (ref_tol_deg)" in str(cal.report)  # the fit saw it
    # The exported recording says the references were hand-placed, so a refit agrees.
    with sf() as s:
        s.execute(update(Rig).where(Rig.name == "bench").values(turntable={"driver": "manual"}))
        s.commit()
    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app),
                                 base_url="http://t") as client:
        r = await client.get(f"/api/v1/campaigns/{cid}/recording.csv", headers=headers)
    lines = r.text.splitlines()
    assert lines[0].endswith(",ref_tol_deg") and all(x.endswith(",2.0") for x in lines[1:])
    assert "pose_q" not in lines[0]  # no pose known: the columns are left out


async def test_board_keeps_an_open_request_and_reissues_with_the_reason(sf) -> None:
    cid = add_campaign(sf, spec=MANUAL_SPEC, rig="bench", state="running")
    board = PlacementBoard(sf, "bench")
    first = board.publish(np.array([0, -1.0, 0]))
    assert first is not None and first["position"] == 3 and first["seq"] == 1
    assert board.publish(np.array([0, -1.0, 0]))["seq"] == 1  # engine re-command: kept
    again = board.publish(np.array([0, -1.0, 0]), reason="y looks up, not down")
    assert again["seq"] == 2 and again["reason"] == "y looks up, not down"
    assert again["state"] == "pending" and again["campaign_id"] == cid


class _StillSensor:
    """A sensor lying still with +z up (what a placed cube reads)."""

    async def acquire(self, n_samples: int) -> Any:
        from drivers.protocols import Acquisition

        return Acquisition((0.0, 0.0, 1.0), (NOISE_G,) * 3, n_samples, 25.0, 0.0, False, 0.1)


async def test_a_confirmation_survives_a_restart_of_the_driver(sf) -> None:
    """The request lives in the database: a new driver (new process) sees the confirmation."""
    cid = add_campaign(sf, spec=MANUAL_SPEC, rig="bench", state="running")
    home = angles_for_reference(np.array([0.0, 0.0, 1.0]))
    before = ManualTurntable(PlacementBoard(sf, "bench"), _StillSensor())
    await before.move_to(home)
    assert not (await before.read_status()).in_position  # nobody confirmed yet
    with sf() as s:
        from service.engine.placement import confirm_request

        confirm_request(s, cid, 4)  # six: +z is position 4
        s.commit()
    after = ManualTurntable(PlacementBoard(sf, "bench"), _StillSensor())  # restarted
    await after.move_to(home)  # the engine re-commands the pending position
    assert (await after.read_status()).in_position
    assert PlacementBoard(sf, "bench").state() == "accepted"
