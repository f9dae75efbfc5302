"""A soak campaign with ``ramp_c_per_min: 0`` (step: the chamber moves at its own rate) on a
chamber without a ramp register: accepted at the door with a duration predicted from the
rig's own rate, refused with the reason where that rate is unknown, completed over the wire
on the twin serving the csz-ezt-430i map; a ramp campaign on that rig refused naming why,
at creation (422) and in ``campaign plan``."""

from __future__ import annotations

import asyncio
import json
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from calibration.thermal_plant import AMBIENT_C
from drivers.clock import VirtualClock
from service.db.models import Campaign, Measurement, Rig
from service.dry_run import check_campaign
from service.engine.calibrate import CalibrationRow
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner
from service.engine.spec import EngineSpec
from simulators.rig import start_sim_rig

SETPOINTS_C = [-10.0, 10.0, 30.0]
STEP_SPEC: dict[str, Any] = {"setpoints_c": SETPOINTS_C, "soak_min": 30, "positions": "six",
                             "samples_per_position": 20, "ramp_c_per_min": 0}


def _ezt(url: str = "tcp://10.0.0.5:502", **chamber: Any) -> dict[str, Any]:
    return {"name": "ezt", "chamber": {"driver": "modbus", "url": url, "map": "csz-ezt-430i",
                                       "range_c": [-40, 85], **chamber},
            "turntable": {"url": "tcp://10.0.0.6:502"}, "sensors": [{"url": "/dev/ttyUSB0"}]}


def test_a_step_is_predicted_from_the_rigs_own_rate() -> None:
    check = check_campaign(EngineSpec.model_validate(STEP_SPEC),
                           _ezt(max_rate_c_per_min=4.0), "ezt")
    assert check.ok, check.issues
    assert check.prediction is not None
    # 23 → -10 → 10 → 30 °C at the chamber's own 4 °C/min: 73 °C, 18.25 min.
    travel_c = abs(SETPOINTS_C[0] - AMBIENT_C) + 20.0 + 20.0
    assert check.prediction["ramp_s"] == pytest.approx(travel_c / 4.0 * 60.0)
    assert check.predicted_duration_s == pytest.approx(
        check.prediction["ramp_s"] + check.prediction["soak_s"]
        + check.prediction["positions_s"])


def test_a_step_on_a_rig_that_does_not_state_its_rate_is_refused_with_the_fix() -> None:
    check = check_campaign(EngineSpec.model_validate(STEP_SPEC), _ezt(), "ezt")
    assert not check.ok and check.predicted_duration_s is None
    [issue] = check.issues
    assert issue.loc == ("ramp_c_per_min",)
    assert issue.msg == (
        "ramp_c_per_min 0 on rig 'ezt': its chamber (map csz-ezt-430i) steps to each setpoint "
        "at its own rate, which the rig does not state, so the campaign's duration cannot be "
        "predicted; set chamber.max_rate_c_per_min, or limits.max_ramp_c_per_min of map "
        "csz-ezt-430i to the chamber's fastest rate (its data sheet)")


def test_zero_on_the_sim_twin_names_its_map_and_a_soak_rate_is_still_fine() -> None:
    sim = {"name": "sim", "chamber": {"driver": "sim"}, "turntable": {"driver": "sim"}}
    check = check_campaign(EngineSpec.model_validate(STEP_SPEC), sim, "sim")
    [issue] = check.issues
    assert issue.loc == ("ramp_c_per_min",)
    assert "map eurotherm-3216 has a ramp register" in issue.msg
    assert check_campaign(EngineSpec.model_validate({**STEP_SPEC, "ramp_c_per_min": 2}),
                          sim, "sim").ok


def test_a_ramp_method_needs_a_ramp_in_the_spec_and_on_the_rig(
        client: TestClient, auth, settings, monkeypatch: pytest.MonkeyPatch,  # type: ignore[no-untyped-def]
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from service.cli import main

    rig = _ezt(max_rate_c_per_min=4.0)
    assert client.post("/api/v1/rigs", json=rig, headers=auth["admin"]).status_code == 201
    ramp = {"rig": "ezt", "sensor": "SN-0001", "method": "ramp", "setpoints_c": [-20, 40],
            "ramp_c_per_min": 1}
    r = client.post("/api/v1/campaigns", json=ramp, headers=auth["operator"])
    assert r.status_code == 422, r.text
    assert ("method 'ramp' needs a controlled ramp: map csz-ezt-430i has no static ramp"
            in json.dumps(r.json()["detail"], ensure_ascii=False))
    r = client.post("/api/v1/campaigns", json={**ramp, "rig": "sim", "ramp_c_per_min": 0},
                    headers=auth["operator"])
    assert r.status_code == 422, r.text
    assert "ramp_c_per_min 0 means step" in json.dumps(r.json()["detail"])
    step = client.post("/api/v1/campaigns", headers=auth["operator"],
                       json={"rig": "ezt", "sensor": "SN-0001", **STEP_SPEC})
    assert step.status_code == 201, step.text
    assert step.json()["predicted_duration_s"] > 73 / 4.0 * 60.0

    monkeypatch.setenv("SOAKCAL_DATABASE_URL", settings.database_url)
    assert main(["campaign", "plan", "--rig", "ezt", "--method", "ramp",
                 "--setpoints=-20,40"]) == 2
    assert "method: method 'ramp' needs a controlled ramp" in capsys.readouterr().err
    assert main(["campaign", "plan", "--rig", "ezt", "--positions", "six",
                 "--ramp-c-per-min", "0"]) == 0
    assert "plan on rig 'ezt': 11 steps × 6 positions" in capsys.readouterr().out


def _fake_calibrate(columns, provenance):  # type: ignore[no-untyped-def]
    return CalibrationRow(valid_lo_c=min(columns["sensor_c"]),
                          valid_hi_c=max(columns["sensor_c"]), rmse_ug=1.0,
                          model_version="fake", model={"fake": True}, report={},
                          provenance=provenance)


def test_a_step_campaign_completes_over_the_wire_on_a_map_without_a_ramp(sf) -> None:  # type: ignore[no-untyped-def]
    async def run() -> tuple[int, str]:
        clock = VirtualClock(idle_wall_s=0.0003)
        async with start_sim_rig(clock, seed=3, chamber_map="csz-ezt-430i") as sim:
            cfg = {**_ezt(sim.chamber_url, max_rate_c_per_min=5.0),
                   "turntable": {"driver": "modbus", "url": sim.table_url},
                   "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}
            with sf() as s:
                s.add(Rig(name="ezt", chamber=cfg["chamber"], turntable=cfg["turntable"],
                          sensors=cfg["sensors"]))
                s.flush()
                c = Campaign(rig="ezt", sensor="SN-T", spec=dict(STEP_SPEC), state="queued",
                             progress={}, steps_log=[])
                s.add(c)
                s.commit()
                cid = c.id
            async with open_rig(cfg, clock) as devices:
                runner = CampaignRunner(sf, cid, devices, clock, calibrate=_fake_calibrate)
                return cid, await asyncio.wait_for(runner.run(), 60.0)

    cid, state = asyncio.run(run())
    assert state == "completed"
    with sf() as s:
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
    assert Counter((m.step, m.position) for m in rows) == {
        (st, p): 1 for st in range(3) for p in range(6)}
    for m in rows:  # the chamber stepped to each setpoint and the die followed it
        assert abs(m.sensor_c - SETPOINTS_C[m.step]) < 3.0
