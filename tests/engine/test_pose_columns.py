"""The pose the rig commanded, recorded with every measurement (issue 22, turntable
geometry; docs/recording.md, ``pose_q*``): a motorised campaign's export carries it after
``ref_z``, one consistent with ``ref_*``; rows without a pose export as before."""

from __future__ import annotations

import asyncio
import csv
import io

import pytest

from engine_helpers import (  # isort: skip
    POSE_COLUMNS, SMALL_SPEC, SQLITE_ONLY, add_campaign, assert_poses_give_references,
    fake_calibrate)
from sqlalchemy import select

from calibration.recording import parse_recording
from drivers.clock import VirtualClock
from drivers.geometry import angles_for_reference, pose_quaternion
from service.api.recording_csv import RECORDING_COLUMNS, render_recording_csv
from service.db.models import Campaign, Measurement
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner

SIM = {"name": "sim", "chamber": {"driver": "sim", "range_c": [-70, 180]},
       "turntable": {"driver": "sim"}}


def _measurements(sf, cid: int) -> list[Measurement]:  # type: ignore[no-untyped-def]
    with sf() as s:
        return list(s.scalars(select(Measurement).where(Measurement.campaign_id == cid)
                              .order_by(Measurement.t_s, Measurement.step,
                                        Measurement.position)))


def _parse(text: str) -> tuple[list[str], list[dict[str, str]]]:
    reader = csv.DictReader(io.StringIO(text))
    return list(reader.fieldnames or []), list(reader)


async def test_a_soak_campaign_records_the_commanded_pose_of_every_reading(sf) -> None:  # type: ignore[no-untyped-def]
    spec = {**SMALL_SPEC, "setpoints_c": [10.0, 30.0], "samples_per_position": 20,
            "soak_min": 10}
    cid = add_campaign(sf, spec)
    clock = VirtualClock()
    async with open_rig(SIM, clock, seed=4, sim_options={"modbus_in_memory": True}) as dev:
        state = await asyncio.wait_for(
            CampaignRunner(sf, cid, dev, clock, calibrate=fake_calibrate).run(), 60.0)
    with sf() as s:
        assert state == "completed", s.get(Campaign, cid).error
    rows = _measurements(sf, cid)
    assert len(rows) == 12
    text = render_recording_csv(rows)
    header, parsed = _parse(text)
    at = header.index("ref_z") + 1
    assert tuple(header[at:at + 4]) == POSE_COLUMNS
    assert [c for c in header if c not in POSE_COLUMNS] == list(RECORDING_COLUMNS)
    assert_poses_give_references(parsed)
    # The twin's table is 3-axis: each pose is that of the angles the engine commanded.
    for row in parsed:
        ref = [float(row[c]) for c in ("ref_x", "ref_y", "ref_z")]
        assert tuple(float(row[c]) for c in POSE_COLUMNS) == pose_quaternion(
            angles_for_reference(ref, 3))
    # still a recording the commands read (an unknown column is kept, not refused)
    assert parse_recording(text).header == header


def _row(t_s: float, pose: tuple[float, float, float, float] | None) -> Measurement:
    q = pose or (None, None, None, None)
    return Measurement(step=0, position=0, t_s=t_s, setpoint_c=20.0, chamber_c=20.0,
                       sensor_c=21.0, ref_x=0.0, ref_y=0.0, ref_z=1.0, ax=0.0, ay=0.0,
                       az=1.0, n=10, **dict(zip(POSE_COLUMNS, q, strict=True)))


def test_rows_without_a_pose_export_as_before_and_a_missing_one_is_empty() -> None:
    header, _ = _parse(render_recording_csv([_row(1.0, None), _row(2.0, None)]))
    assert header == list(RECORDING_COLUMNS)  # no pose anywhere: the old export, unchanged
    header, parsed = _parse(render_recording_csv(
        [_row(1.0, None), _row(2.0, (1.0, 0.0, 0.0, 0.0))], ref_tol_deg=2.0))
    assert header[-1] == "ref_tol_deg" and set(POSE_COLUMNS) <= set(header)
    assert [parsed[0][c] for c in POSE_COLUMNS] == ["", "", "", ""]  # not known: empty
    assert [parsed[1][c] for c in POSE_COLUMNS] == ["1.0", "0.0", "0.0", "0.0"]


def test_a_hand_step_off_the_schedule_is_stored_as_the_reference_it_gives() -> None:
    """A hand axis at its 45° step where the schedule asked for 44.7° (within the indexer's
    0.5° tolerance): the row's reference is the direction the commanded pose puts gravity
    along, not the schedule's, 0.26° (4.5 mg) across it (a reference-mode fit takes ref_* as the
    truth). Where the two agree the schedule's reference is kept to the bit."""
    import numpy as np

    from drivers.geometry import reference_for_angles
    from service.engine.runner import commanded_reference

    asked = reference_for_angles((30.0, 44.7))
    pose = dict(zip(POSE_COLUMNS, pose_quaternion((30.0, 45.0)), strict=True))
    stored = np.array(commanded_reference(asked, pose))
    np.testing.assert_allclose(stored, reference_for_angles((30.0, 45.0)), atol=1e-12)
    assert np.degrees(np.arccos(stored @ asked)) == pytest.approx(0.26, abs=0.01)  # 4.5 mg
    same = dict(zip(POSE_COLUMNS, pose_quaternion((30.0, 44.7)), strict=True))
    assert commanded_reference(asked, same) == tuple(asked)
    assert commanded_reference(asked, dict.fromkeys(POSE_COLUMNS)) == tuple(asked)


@SQLITE_ONLY  # the diagnosis of what was stored; the storing is tested on both above
async def test_a_tilted_base_on_the_twin_rig_is_named_from_the_engines_recording(sf) -> None:  # type: ignore[no-untyped-def]
    """End to end (issue 22): the twin rig's table base tilted 200 / −100 µrad; the engine
    runs Table 1 in a balanced order per plateau and records each reading's commanded pose;
    `diagnose` on the exported recording names the table's geometry with the lab-frame
    tilt it was given."""
    import numpy as np

    from calibration.discrepancy import diagnose
    from simulators.effects import TurntableGeometry
    from simulators.truth import SensorTruth

    truth = SensorTruth.adxl355_typical(seed=6, effects=[
        TurntableGeometry(base_tilt_rad=np.array([200e-6, -100e-6]))])
    spec = {**SMALL_SPEC, "setpoints_c": [-20.0, 10.0, 40.0, 60.0], "positions": "table1",
            "samples_per_position": 20, "soak_min": 10, "position_order": "balanced"}
    cid = add_campaign(sf, spec)
    clock = VirtualClock()
    async with open_rig(SIM, clock, seed=4, sim_options={"modbus_in_memory": True,
                                                         "truth": truth}) as dev:
        state = await asyncio.wait_for(
            CampaignRunner(sf, cid, dev, clock, calibrate=fake_calibrate).run(), 120.0)
    with sf() as s:
        assert state == "completed", s.get(Campaign, cid).error
    d = diagnose(parse_recording(render_recording_csv(_measurements(sf, cid))), n_null=60,
                 seed=1)
    named = [f for f in d.findings if f.effect == "turntable_geometry"]
    assert named, [f.effect for f in d.findings]
    p, sd = named[0].parameters, named[0].parameter_sd
    assert p["shape"] == 3.0
    # 205.4 ± 5.0 and −97.3 ± 7.5 µrad on this draw
    assert abs(p["tilt_x_urad"] - 200.0) <= 4 * sd["tilt_x_urad"] and sd["tilt_x_urad"] < 20
    assert abs(p["tilt_y_urad"] + 100.0) <= 4 * sd["tilt_y_urad"] and sd["tilt_y_urad"] < 20
