"""Issue 22: a tilted table base read through the poses a recording gives its readings
(``pose_q*``, calibration/table_pose.py). Without them a tilt on Table 1 in a random order
is reported only as a structure the references cannot name (each Table 1 great circle is
two half-sweeps of this rig's table); with them it is two lab-frame angles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import table_pose
from calibration.discrepancy import diagnose
from calibration.errors import RecordingError
from calibration.recording import Recording, write_recording
from drivers.geometry import angles_for_reference, reference_for_angles
from service.cli import main
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


def _pose(angles_deg) -> np.ndarray:
    """R (sensor to lab) of the rig's axis convention, Rx(a0)·Ry(a1)·Rz(a2)."""
    a = [math.radians(x) for x in angles_deg]
    cx, sx, cy, sy, cz, sz = (math.cos(a[0]), math.sin(a[0]), math.cos(a[1]), math.sin(a[1]),
                              math.cos(a[2]), math.sin(a[2]))
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rx @ ry @ rz


def _posed_columns(tilt_urad, seed: int = 6, poses: bool = True) -> dict[str, np.ndarray]:
    """A twin campaign on Table 1 in a random order per plateau, its table base tilted by
    ``tilt_urad`` about lab x, y as this rig's table holds each pose (the engine's
    commanded angles), with the poses as the engine records them."""
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=seed), setpoints_c=ONE_WAY,
                            seed=10 + seed, position_order="random", position_order_seed=3,
                            record_poses=False)
    ref = rec.ref_g
    R = np.array([_pose(angles_for_reference(r, 3)) for r in ref])
    cols = {k: np.array(v) for k, v in rec.columns.items()}
    assert not set(table_pose.POSE_COLUMNS) & set(cols)
    q = table_pose.pose_quaternion(R)
    turn = table_pose.lab_tilt_columns(q, np.linalg.norm(ref, axis=1))
    moved = turn @ (np.asarray(tilt_urad, float) * 1e-6)
    for j, c in enumerate(("ax", "ay", "az")):  # the scale is 1 within 1e-3 of 20 µrad
        cols[c] = cols[c] + moved[:, j]
    if poses:
        cols.update({c: q[:, j] for j, c in enumerate(table_pose.POSE_COLUMNS)})
    return cols


def test_the_pose_columns_give_back_the_references_of_the_rigs_angles():
    rng = np.random.default_rng(0)
    angles = rng.uniform(-180.0, 180.0, (20, 3))
    R = np.array([_pose(a) for a in angles])
    q = table_pose.pose_quaternion(R)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0) and np.all(q[:, 0] >= 0)
    ref = np.array([reference_for_angles(tuple(a)) for a in angles])
    cols = {"t_s": np.arange(20.0), "chamber_c": np.full(20, 25.0),
            "ax": ref[:, 0], "ay": ref[:, 1], "az": ref[:, 2],
            "ref_x": ref[:, 0], "ref_y": ref[:, 1], "ref_z": ref[:, 2],
            **{c: q[:, j] for j, c in enumerate(table_pose.POSE_COLUMNS)}}
    R_t = table_pose.pose_rows(table_pose.read_poses(Recording.from_columns(cols)), (0, 1, 2))
    assert np.allclose(R_t, R.transpose(0, 2, 1), atol=1e-12)
    assert np.allclose(R_t[:, :, 2], ref, atol=1e-12)


def test_a_tilted_base_on_table_1_is_named_with_its_tilt_through_the_poses():
    d = diagnose(Recording.from_columns(_posed_columns((20.0, -10.0))), n_null=60, seed=6)
    assert [f.effect for f in d.findings] == ["turntable_geometry"]
    p, sd = d.findings[0].parameters, d.findings[0].parameter_sd
    assert p["shape"] == 3.0 and p["n_poses"] == 24
    assert abs(p["tilt_x_urad"] - 20.0) <= 3 * sd["tilt_x_urad"] < 6.0
    assert abs(p["tilt_y_urad"] + 10.0) <= 3 * sd["tilt_y_urad"] < 6.0
    assert "about lab x" in d.findings[0].explanation
    # The same readings without the poses: the references alone do not name it.
    plain = diagnose(Recording.from_columns(_posed_columns((20.0, -10.0), poses=False)),
                     n_null=60, seed=6)
    assert "turntable_geometry" not in [f.effect for f in plain.findings]


def test_an_untilted_base_with_poses_gives_no_finding():
    assert diagnose(Recording.from_columns(_posed_columns((0.0, 0.0))), n_null=60,
                    seed=6).findings == []


def test_a_pose_that_disagrees_with_its_reference_is_refused_with_where(tmp_path, capsys):
    cols = _posed_columns((0.0, 0.0))
    cols["pose_qx"], cols["pose_qy"] = cols["pose_qy"].copy(), cols["pose_qx"].copy()
    with pytest.raises(RecordingError, match="from ref_"):
        diagnose(Recording.from_columns(cols), n_null=20, seed=0)
    path = tmp_path / "swapped.csv"
    write_recording(path, cols)
    assert main(["diagnose", str(path), "--n-null", "20"]) == 2
    err = capsys.readouterr().err
    assert "swapped.csv:" in err and "column 'pose_qw'" in err
    assert "check the pose columns' order (w, x, y, z)" in err


def test_the_report_says_the_poses_were_read(tmp_path, capsys):
    path = tmp_path / "posed.csv"
    write_recording(path, _posed_columns((0.0, 0.0)))
    assert main(["diagnose", str(path), "--n-null", "20"]) == 0
    assert "references and the table's poses;" in capsys.readouterr().out
    cols = _posed_columns((0.0, 0.0), poses=False)
    write_recording(path, cols)
    assert main(["diagnose", str(path), "--n-null", "20"]) == 0
    out = capsys.readouterr().out
    assert "; references;" in out and "table's poses" not in out


def test_a_recording_with_poses_keeps_no_text_for_them(tmp_path):
    """The pose columns are numbers the reader parses: a file of them keeps no text
    (calibrate and diagnose read with raw_cells=False; issue 22, memory: kept as text they
    cost calibrate a third more on a 1 M-reading recording)."""
    from calibration.recording import read_recording

    path = tmp_path / "posed.csv"
    write_recording(path, _posed_columns((0.0, 0.0)))
    rec = read_recording(path, raw_cells=False)
    assert rec.cells is None
    assert np.allclose(table_pose.read_poses(rec)[:, 0], rec.columns["pose_qw"])


def test_a_turn_the_recorded_poses_do_not_explain_is_said_so():
    """A turn of each pose that is not a tilted base of this table (here a tilt in the
    minimal-rotation convention, as a wobbling axis would turn poses its own way), visited
    in a random order with the poses recorded: listed not separable from a coupling, and the
    report says the base's tilt was tested through the poses and does not explain it."""
    from simulators import effects as E  # noqa: N812 (as the other discrepancy tests)

    tilt = E.TurntableGeometry(base_tilt_rad=np.array([3e-3, -2e-3]), through_poses=False)
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=6, effects=[tilt]),
                            setpoints_c=ONE_WAY, seed=16, position_order="random",
                            position_order_seed=3)
    d = diagnose(rec, n_null=30, seed=6)
    turned = [f for f in d.findings if f.effect == "not_identifiable"]
    assert turned and "turntable_geometry" in turned[0].where["candidates"]
    text = turned[0].explanation
    assert "a tilted table base, tested through the recorded poses, does not explain it" in text
    assert "repeat the tumble with the sensor remounted at 90°" in text
    assert "record the gimbal angles" not in text
