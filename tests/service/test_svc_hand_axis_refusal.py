"""A 1-axis motorised stage with the second axis by hand (docs/manual-fixtures.md): a
schedule it cannot reach is refused at creation (REST 422, ``campaign plan`` exit 2) with
the reason the engine would fail with at start; what it can reach is accepted; its
campaigns are fitted as hand-placed (``ref_tol_deg``), in the service and in the export."""

from __future__ import annotations

import contextlib
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from calibration.placement import REF_TOL_COLUMN
from service.db.models import Campaign, Measurement, Rig
from service.dry_run import check_campaign
from service.engine.spec import EngineSpec

QUARTER_STEPS = [0, 90, 180, 270]
SPEC: dict[str, Any] = {"setpoints_c": [5.0, 20.0], "soak_min": 10,
                        "samples_per_position": 30, "move_timeout_s": 3600.0}


def _stage(steps: list[float] | None = QUARTER_STEPS, name: str = "stage") -> dict[str, Any]:
    hand = {} if steps is None else {"steps_deg": steps}
    return {"name": name,
            "chamber": {"driver": "modbus", "url": "tcp://10.0.0.5:502", "map": "eurotherm3216",
                        "range_c": [-40, 85]},
            "turntable": {"url": "rtu:///dev/ttyUSB1?baudrate=38400",
                          "map": "leadshine-rs485-pr", "axes": 1, "hand_axis": hand},
            "sensors": [{"url": "/dev/ttyUSB0"}]}


def _check(positions: str, rig: dict[str, Any]) -> Any:
    return check_campaign(EngineSpec.model_validate({**SPEC, "positions": positions}), rig,
                          rig["name"])


def test_corners_on_quarter_steps_are_refused_naming_the_pose_they_need() -> None:
    check = _check("cube14", _stage())
    assert not check.ok and check.predicted_duration_s is None
    [issue] = check.issues
    assert issue.loc == ("positions",) and issue.value == "cube14"
    # Position 6 is the first corner, (−1, −1, −1)/√3: the motor at asin(y) = −35.3°,
    # the hand at atan2(−x, z) = 135° (or the other pose); neither hand angle is a step.
    assert issue.msg.startswith(
        "schedule 'cube14': rig 'stage' (one motorised axis, the second by hand) cannot "
        "reach position 6 (ref (-0.577, -0.577, -0.577) g) (and 7 more of its 14 "
        "positions): needs motor -35.3° with hand 135.0° or motor -144.7° with hand -45.0°; "
        "the hand axis stops only at 0°, 90°, 180°, 270° and the motor reaches ±360°; "), \
        issue.msg
    assert issue.msg.endswith("add the indexer steps they need to "
                              "turntable.hand_axis.steps_deg, or use a schedule whose "
                              "positions the stage reaches (e.g. six with steps of 90°)")


def test_what_the_stage_reaches_is_accepted_with_a_prediction() -> None:
    assert _check("six", _stage()).ok
    assert _check("cube14", _stage([0, 45, 90, 135, 180, 225, 270, 315])).ok
    free = _check("cube14", _stage(None))  # no steps: the hand axis turns to any angle
    assert free.ok and free.predicted_duration_s is not None and free.predicted_duration_s > 0
    two_axes = {**_stage(), "turntable": {"url": "tcp://10.0.0.6:502"}}
    assert _check("cube14", two_axes).ok  # a motorised 2-axis table: no hand-axis check


def test_rest_and_plan_refuse_an_unreachable_schedule_at_creation(
        client: TestClient, auth, settings, monkeypatch: pytest.MonkeyPatch,  # type: ignore[no-untyped-def]
        capsys: pytest.CaptureFixture[str]) -> None:
    from service.cli import main

    r = client.post("/api/v1/rigs", json=_stage(), headers=auth["admin"])
    assert r.status_code == 201, r.text
    body = {"rig": "stage", "sensor": "SN-0001", **SPEC}
    r = client.post("/api/v1/campaigns", json={**body, "positions": "cube14"},
                    headers=auth["operator"])
    assert r.status_code == 422, r.text
    detail = json.dumps(r.json()["detail"], ensure_ascii=False)
    assert "cannot reach position 6" in detail
    assert "the hand axis stops only at 0°, 90°, 180°, 270°" in detail
    r = client.post("/api/v1/campaigns", json={**body, "positions": "six"},
                    headers=auth["operator"])
    assert r.status_code == 201, r.text

    monkeypatch.setenv("SOAKCAL_DATABASE_URL", settings.database_url)
    assert main(["campaign", "plan", "--rig", "stage", "--positions", "cube14",
                 "--setpoints", "5,20"]) == 2
    err = capsys.readouterr().err
    assert "positions: schedule 'cube14': rig 'stage' (one motorised axis" in err
    assert "with hand -45.0°" in err
    assert main(["campaign", "plan", "--rig", "stage", "--positions", "six",
                 "--setpoints", "5,20"]) == 0
    assert "plan on rig 'stage': 2 steps × 6 positions" in capsys.readouterr().out


def _add_rig_and_campaign(sf: sessionmaker[Session], rig: dict[str, Any]) -> int:
    with sf() as s:
        s.add(Rig(name=rig["name"], chamber=rig["chamber"], turntable=rig["turntable"],
                  sensors=rig["sensors"]))
        s.flush()
        c = Campaign(rig=rig["name"], sensor="SN-T", spec={**SPEC, "positions": "six"},
                     state="completed", progress={}, steps_log=[])
        s.add(c)
        s.flush()
        s.add(Measurement(campaign_id=c.id, sensor="SN-T", step=0, position=0, t_s=1.0,
                          setpoint_c=5.0, chamber_c=5.0, sensor_c=5.2, ref_x=0.0, ref_y=0.0,
                          ref_z=1.0, ax=0.001, ay=-0.002, az=1.0003, sd_x=1e-5, sd_y=1e-5,
                          sd_z=1e-5, n=30))
        s.commit()
        return c.id


@pytest.mark.parametrize(("rig", "hand_placed"), [
    (_stage(), True), (_stage(None, name="free"), True),
    ({**_stage(name="motor2"), "turntable": {"url": "tcp://10.0.0.6:502"}}, False)])
def test_the_export_of_a_hand_axis_rig_says_its_references_are_hand_placed(
        client: TestClient, auth, sf, rig: dict[str, Any], hand_placed: bool) -> None:  # type: ignore[no-untyped-def]
    cid = _add_rig_and_campaign(sf, rig)
    r = client.get(f"/api/v1/campaigns/{cid}/recording.csv", headers=auth["viewer"])
    assert r.status_code == 200, r.text
    header, row = r.text.splitlines()[:2]
    assert header.endswith(f",{REF_TOL_COLUMN}") is hand_placed
    assert row.endswith(",2.0") is hand_placed


@pytest.mark.parametrize(("rig", "hand_placed"), [
    (_stage(), True), ({**_stage(name="bench"), "turntable": {"driver": "manual"}}, True),
    ({**_stage(name="motor2"), "turntable": {"url": "tcp://10.0.0.6:502"}}, False)])
def test_the_manager_fits_a_hand_axis_rigs_campaign_as_hand_placed(
        sf, monkeypatch: pytest.MonkeyPatch, tmp_path: Path,  # type: ignore[no-untyped-def]
        rig: dict[str, Any], hand_placed: bool) -> None:
    """The manager hands the runner the hand-placed calibrate step (every row gets
    ``ref_tol_deg`` = 2) for a hand axis as for a manual fixture, and not for a motor table."""
    import asyncio

    from service.engine import calibrate as calibrate_mod
    from service.engine import manager as manager_mod

    cid = _add_rig_and_campaign(sf, rig)
    seen: dict[str, Any] = {}
    fitted: dict[str, Any] = {}

    @contextlib.asynccontextmanager
    async def fake_open_rig(cfg: dict[str, Any], clock: Any, **_: Any) -> AsyncIterator[Any]:
        yield object()

    class FakeRunner:
        def __init__(self, sf_: Any, campaign_id: int, devices: Any, clock: Any,
                     **options: Any) -> None:
            seen.update(options, campaign_id=campaign_id)

        async def run(self) -> str:
            return "completed"

    def fake_fit(columns: dict[str, list[float]], provenance: dict[str, Any]) -> Any:
        fitted.update(columns=columns, provenance=provenance)

    monkeypatch.setattr(manager_mod, "open_rig", fake_open_rig)
    monkeypatch.setattr(manager_mod, "CampaignRunner", FakeRunner)
    monkeypatch.setattr(calibrate_mod, "calibrate_columns", fake_fit)  # the fit it wraps
    asyncio.run(manager_mod.CampaignManager(sf, owner="test")._run(rig["name"], cid))
    assert seen["campaign_id"] == cid
    if not hand_placed:  # the runner's own (exact-reference) fit
        assert "calibrate" not in seen
        return
    seen["calibrate"]({"t_s": [0.0, 1.0]}, {"campaign": cid})
    assert fitted["columns"][REF_TOL_COLUMN] == [2.0, 2.0]
    assert fitted["provenance"] == {"campaign": cid, REF_TOL_COLUMN: 2.0, "placement": "manual"}
