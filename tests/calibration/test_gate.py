"""The gate: orientations counted within the noise, what they identify, physical sense."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration import cli, fit, gate, schedules, sfem
from calibration.errors import NotIdentifiable
from calibration.model_file import load_model
from calibration.recording import write_recording
from calibration.thermal import ThermalModel, fit_campaign
from simulators.warmup_log import warmup_log
from tests.calibration.log_writers import flight_samples


def _args(recording: Path, output: Path, **kw: object) -> object:
    class A:
        pass

    a = A()
    a.recording, a.output = str(recording), str(output)
    for k, v in kw.items():
        setattr(a, k, v)
    return a


def _calibrate(tmp_path: Path, rec: object, **kw: object) -> tuple[int, Path]:
    """Write ``rec`` and run ``soakcal calibrate`` on it: (exit status, model path)."""
    src, out = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, rec)
    return cli.run_calibrate(_args(src, out, **kw)), out


def test_noise_scatter_of_one_orientation_is_one_orientation() -> None:
    rng = np.random.default_rng(1)
    raw = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 2e-3, (5000, 3))
    ori = gate.distinct_orientations(raw)
    assert ori.count == 1
    assert ori.names() == "z up"


def test_a_sphere_of_24_is_24_orientations_however_often_visited() -> None:
    dirs = schedules.sphere(24)
    ori = gate.distinct_orientations(np.vstack([dirs] * 5))
    assert ori.count == 24
    np.testing.assert_array_equal(ori.counts, 5)


def test_a_norm_fit_of_one_noisy_orientation_is_refused_not_fitted() -> None:
    # The case: 10,000 rows of one resting orientation once passed as positions
    # and gave a -70 g bias.
    rng = np.random.default_rng(2)
    raw = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 1e-3, (10_000, 3))
    with pytest.raises(NotIdentifiable, match=r"1 distinct orientation\(s\) \(z up\)"):
        fit.fit_norm(raw)


def test_a_model_with_a_70_g_bias_is_refused() -> None:
    p = sfem.identity_vector()
    p[2] = -70.0
    model = ThermalModel(coeffs=p[:, None], t_centre_c=0.0, t_scale_c=1.0, valid_c=None,
                         mode="norm", identifiable=np.ones(12, bool))
    rec = warmup_log(seconds=20, rate_hz=10)[0]
    with pytest.raises(gate.GateRefusal, match=r"fitted bias bz = -70 g is not physical"):
        gate.check_model(model, rec)


def test_a_scale_of_0_014_is_refused() -> None:
    p = sfem.identity_vector()
    p[5] = 0.014
    model = ThermalModel(coeffs=p[:, None], t_centre_c=0.0, t_scale_c=1.0, valid_c=None,
                         mode="norm", identifiable=np.ones(12, bool))
    rec = warmup_log(seconds=20, rate_hz=10)[0]
    with pytest.raises(gate.GateRefusal, match=r"fitted scale sz = 0.014 is not physical"):
        gate.check_model(model, rec)


def test_one_orientation_warmup_is_calibrated_as_a_bias_change(tmp_path: Path,
                                                                 capsys) -> None:
    rec, truth = warmup_log(seconds=200, rate_hz=100, seed=3)
    status, out = _calibrate(tmp_path, rec, json=True)
    assert status == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["mode"] == "warmup" and doc["orientations"] == 1
    assert sorted(doc["fitted"]) == ["bx", "by", "bz"]
    assert {"sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz"} == set(doc["held"])
    assert doc["degree"] >= 1
    model = load_model(out)
    assert model.mode == "warmup"
    lo, hi = model.valid_c
    assert lo == pytest.approx(float(rec.temperature_c().min()))
    assert hi == pytest.approx(float(rec.temperature_c().max()))
    # The bias change over the span (10 %..90 %: a polynomial's ends carry the most
    # noise) is the truth's within 40 µg, about one capture's noise (1 mg/sqrt(500)).
    a, b = lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)
    change = model.params_vector_at(b)[:3] - model.params_vector_at(a)[:3]
    true_change = (truth.bias_g(np.array([b])) - truth.bias_g(np.array([a])))[0]
    np.testing.assert_allclose(change, true_change, atol=40e-6)
    # Never a distortion: z down and x up stay 1 g readings after compensation.
    for up in ([0, 0, -1.0], [1.0, 0, 0], [0, 1.0, 0]):
        cal = model.compensate(np.array([up]), np.array([hi]))
        assert abs(np.linalg.norm(cal) - 1.0) < 3e-3, (up, cal)
    # Held-out error is below the uncompensated one (the drift is 1.4 mg on z).
    held = doc["heldout_rms_mg_xyz"]
    assert held["compensated"][2] < 0.3 * held["uncompensated"][2]


def test_a_warmup_turned_over_once_uses_both_orientations(tmp_path: Path, capsys) -> None:
    rec, truth = warmup_log(seconds=200, rate_hz=50, seed=4,
                            segments=[(100.0, (0, 0, -1))])
    status, out = _calibrate(tmp_path, rec)
    assert status == 0
    text = capsys.readouterr().out
    assert "2 orientation(s) (z up, z down)" in text
    assert "fitted: bx, by, bz" in text
    model = load_model(out)
    lo, hi = model.valid_c
    a, b = lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)
    change = model.params_vector_at(b)[:3] - model.params_vector_at(a)[:3]
    true_change = (truth.bias_g(np.array([b])) - truth.bias_g(np.array([a])))[0]
    # 100 s per orientation at 50 Hz: captures' noise 63 µg, twice that for a change.
    np.testing.assert_allclose(change, true_change, atol=130e-6)


def test_one_orientation_without_temperature_is_refused_in_one_line(tmp_path: Path) -> None:
    rec, _ = warmup_log(seconds=20, rate_hz=50)
    cols = {k: rec.columns[k] for k in ("t_s", "ax", "ay", "az")}
    cols["chamber_c"] = np.full(len(rec), np.nan)
    src, out = tmp_path / "still.csv", tmp_path / "model.json"
    write_recording(src, cols)
    r = subprocess.run([sys.executable, "-m", "service.cli", "calibrate", str(src), "-o",
                        str(out)], capture_output=True, text=True, cwd=Path(__file__).parents[2])
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "1 distinct orientation(s) (z up)" in lines[0]
    assert "no temperature: nothing can be calibrated" in lines[0]
    assert "record at least 10 distinct orientations" in lines[0]
    assert lines[0].count("still.csv") == 1
    assert not out.exists()


def test_diagnose_cannot_judge_a_warmup_with_calibrates_reason(tmp_path: Path,
                                                                capsys) -> None:
    n = 72  # 72 identical rows: no mismatch with rmse 0, but "cannot judge"
    src = tmp_path / "same.csv"
    write_recording(src, {"t_s": np.arange(n) * 10.0, "sensor_c": np.full(n, 25.0),
                          "ax": np.zeros(n), "ay": np.zeros(n), "az": np.ones(n)})
    args = _args(src, tmp_path / "unused.json", json=True, model=None, n_null=None,
                 against=None, write_twin=None, report_dir=None, seed=None)
    assert cli.run_diagnose(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["verdict"] == "cannot judge"
    assert doc["mismatch"] is None
    assert doc["reason"].startswith("1 distinct orientation(s) (z up) and capture "
                                    "temperatures spanning 0.00 °C")
    assert doc["baseline"]["rmse_ug"] is None


def test_a_joint_fit_that_did_not_converge_is_refused() -> None:
    _, rec = thermal_sim.campaign(seed=5, setpoints=(-20.0, 20.0, 60.0))
    result = fit_campaign(rec)  # converged: passes the gate inside fit_campaign
    result.report["joint_fit"]["success"] = False
    result.report["joint_fit"]["message"] = "max evaluations"
    with pytest.raises(gate.GateRefusal, match="joint thermal fit did not converge"):
        gate.check_thermal_fit(result, rec)


def test_an_sfem_models_valid_range_covers_every_reading_it_was_fitted_on() -> None:
    _, rec = thermal_sim.campaign(seed=6, setpoints=(-20.0, 20.0, 60.0))
    model = fit_campaign(rec).model
    temp = rec.temperature_c()
    assert model.first_out_of_range(temp) is None
    assert model.valid_c[0] <= temp.min() and model.valid_c[1] >= temp.max()


def test_a_norm_mode_report_and_model_file_say_what_was_held() -> None:
    from calibration.model_file import dump_model_dict
    from calibration.recording import Recording
    from calibration.report import format_table6

    _, rec = thermal_sim.campaign(seed=7, setpoints=(-20.0, 20.0, 60.0))
    norm = Recording.from_columns({k: v for k, v in rec.columns.items()
                                   if not k.startswith("ref_")})
    result = fit_campaign(norm)
    text = format_table6(result)
    assert "fitted: bx, by, bz, sx, sy, sz, ayx, azx, azy" in text
    assert "mx (held at nominal: a rotation of the sensor frame leaves |g| unchanged" in text
    doc = dump_model_dict(result.model)
    assert sorted(doc["held"]) == ["mx", "my", "mz"]
    assert result.report["held"] == doc["held"]


def test_orientations_at_separate_temperatures_are_refused_by_calibrate_and_diagnose(
        tmp_path: Path, capsys) -> None:
    # A cold log lying on one face and a hot one on another (the shape of a real BMI270
    # pair): the bias change between them is confounded with the change of orientation.
    from calibration.recording import Recording

    cold, _ = warmup_log(seconds=60, rate_hz=50, t_start_c=12.9, t_end_c=13.3, seed=8,
                         up=(0.29, 0.08, -0.95))
    hot, _ = warmup_log(seconds=120, rate_hz=50, t_start_c=49.3, t_end_c=47.2, seed=9,
                        up=(1, 0, 0))
    cols = {k: np.r_[cold.columns[k], hot.columns[k] + (60.0 if k == "t_s" else 0.0)]
            for k in cold.columns}
    src, out = tmp_path / "pair.csv", tmp_path / "model.json"
    write_recording(src, Recording.from_columns(cols))
    assert cli.run_calibrate(_args(src, out)) == 2
    err = capsys.readouterr().err.strip()
    assert "2 orientations recorded at separate temperatures" in err
    assert "x up 47." in err and "record one orientation across the whole" in err
    assert not out.exists()
    args = _args(src, out, json=True, model=None, n_null=None, against=None,
                 write_twin=None, report_dir=None, seed=None)
    assert cli.run_diagnose(args) == 0
    reason = json.loads(capsys.readouterr().out)["reason"]
    assert reason in err  # the same reason, word for word


def test_a_real_bmi270_cold_and_hot_pair_is_refused_not_fitted(tmp_path: Path,
                                                                 capsys) -> None:
    # Vendored slices of a real pair (tests/calibration/data/bmi270/README.md): fitted
    # as one warm-up it once gave bz = -0.93 g.
    from calibration.recording import Recording

    data = Path(__file__).parent / "data" / "bmi270"
    rows = np.vstack([np.loadtxt(data / name, delimiter=",")
                      for name in ("cold_slice.csv", "hot_slice.csv")])
    rec = Recording.from_columns({"t_s": np.arange(len(rows)) / 50.0, "sensor_c": rows[:, 0],
                                  "ax": 4 * rows[:, 1], "ay": 4 * rows[:, 2],
                                  "az": 4 * rows[:, 3]})
    status, out = _calibrate(tmp_path, rec)
    assert status == 2
    err = capsys.readouterr().err
    assert "2 orientations recorded at separate temperatures" in err
    assert "x up 47." in err
    assert not out.exists()


def test_six_axis_directions_per_step_fit_bias_and_scale_and_hold_the_rest(
        tmp_path: Path, capsys) -> None:
    # Six axis directions per step, each visited twice, determine b and S in norm mode
    # (the gate's identifiability on the orientations, spare readings from the repeat
    # visits): fitted, the α and M held and said so. Visited once, the 6 readings leave
    # no spare degree of freedom and the recording is calibrated as a warm-up.
    from calibration.recording import Recording

    _, rec = thermal_sim.campaign(seed=11, setpoints=(-20.0, 20.0, 60.0),
                                  schedule=np.vstack([schedules.six_position()] * 2))
    norm = Recording.from_columns({k: v for k, v in rec.columns.items()
                                   if not k.startswith("ref_")})
    status, out = _calibrate(tmp_path, norm, json=True)
    assert status == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["mode"] == "norm"
    assert doc["orientations"] == 6  # 36 readings: 6 orientations, each twice per step
    assert any(n.startswith("6 distinct orientation(s) (x up, x down, y up, y down and 2 "
                            "more) in 36 reading(s)") for n in doc["notes"])
    assert list(doc["fitted"]) == ["bx", "by", "bz", "sx", "sy", "sz"]
    assert sorted(doc["held"]) == ["ayx", "azx", "azy", "mx", "my", "mz"]
    assert "do not constrain" in doc["held"]["ayx"]


def test_a_twin_sensor_warmup_is_compensated_at_its_orientation_and_not_distorted(
        tmp_path: Path) -> None:
    # The twin's ADXL355 (every SFEM parameter cubic in temperature) warming 10 °C z up:
    # the warm-up model takes out the drift at z up; readings at orientations it never
    # saw keep |g| within what the unseparated scale drift can leave (not 1.41 g).
    from simulators.truth import SensorTruth

    sensor = SensorTruth.adxl355_typical(seed=4)
    rec, _ = warmup_log(seconds=300, rate_hz=50, t_start_c=20.0, t_end_c=30.0, tau_s=150,
                        sensor=sensor, quantum_c=None, seed=12)
    status, out = _calibrate(tmp_path, rec)
    assert status == 0
    model = load_model(out)
    lo, hi = model.valid_c
    die = np.array([lo, hi]) - sensor.temp_offset_c
    up = sensor.ideal_raw_g(np.array([[0, 0, 1.0]] * 2), die)
    drift = up[1] - up[0]
    cal = model.compensate(up, np.array([lo, hi]))
    left = cal[1] - cal[0]
    assert np.max(np.abs(left)) < 0.1 * np.max(np.abs(drift)) + 30e-6, (drift, left)
    side = sensor.ideal_raw_g(np.array([[1.0, 0, 0]] * 2), die)
    norms = np.linalg.norm(model.compensate(side, np.array([lo, hi])), axis=1)
    raw_norms = np.linalg.norm(side, axis=1)
    assert np.all(np.abs(norms - raw_norms) < 5e-3)  # at most the removed drift, mg-level


def test_a_warmup_too_short_to_judge_is_refused_not_a_json_crash(tmp_path: Path,
                                                                  capsys) -> None:
    rec, _ = warmup_log(seconds=12, rate_hz=50, t_start_c=20.0, t_end_c=23.0, tau_s=20)
    status, out = _calibrate(tmp_path, rec, json=True)
    assert status == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "3 capture(s) of 1 orientation(s) (z up): too few to judge a bias change" in err
    assert not out.exists()


def _tilted(face: np.ndarray, toward_x_deg: float, toward_y_deg: float) -> np.ndarray:
    """A unit direction near ``face`` (±z) tilted by the two inclinometer angles."""
    u = np.array([math.tan(math.radians(toward_x_deg)), math.tan(math.radians(toward_y_deg)),
                  1.0]) * np.array([1.0, 1.0, face[2]])
    return u / np.linalg.norm(u)


def test_orientations_near_one_face_are_named_apart_and_unique_ones_simply() -> None:
    tilts = [(0.0, 0.0), (3.0, 0.0), (-3.0, 0.0), (0.0, 3.0), (0.0, -3.0), (6.0, 6.0)]
    dirs = np.vstack([_tilted(np.array([0, 0, -1.0]), *a) for a in tilts]
                     + [[1.0, 0, 0], [0, 0, 1.0]])
    names = gate.direction_names(dirs)
    assert len(set(names)) == len(names)
    assert names[1] == "z down tilted x +3.0° y +0.0°"
    assert names[2] == "z down tilted x -3.0° y +0.0°"
    assert names[5] == "z down tilted x +6.0° y +6.0°"
    assert names[6:] == ["x up", "z up"]  # unique faces keep their simple names
    ori = gate.distinct_orientations(dirs)
    assert ori.count == 8 and ori.name(6) == "x up"
    assert ori.names() == ", ".join(names[:4]) + " and 4 more"


def test_a_refusal_tells_apart_orientations_that_share_a_face(tmp_path: Path) -> None:
    # A board re-placed 8 times within 10° of z down, no temperature: the refusal once named
    # them "z down, z down, z down, z down and 4 more".
    tilts = [(0, 0), (3, 0), (-3, 0), (0, 3), (0, -3), (6, 0), (0, 6), (-6, -6)]
    raw = np.vstack([_tilted(np.array([0, 0, -1.0]), *a) for a in tilts])
    n = len(tilts)
    src, out = tmp_path / "tilts.csv", tmp_path / "model.json"
    write_recording(src, {"t_s": np.arange(n) * 10.0, "chamber_c": np.full(n, np.nan),
                          "ax": raw[:, 0], "ay": raw[:, 1], "az": raw[:, 2],
                          "n": np.full(n, 500.0), "sd_x": np.full(n, 1e-3),
                          "sd_y": np.full(n, 1e-3), "sd_z": np.full(n, 1e-3)})
    r = subprocess.run([sys.executable, "-m", "service.cli", "calibrate", str(src), "-o",
                        str(out)], capture_output=True, text=True, cwd=Path(__file__).parents[2])
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip()
    assert "8 distinct orientation(s) (z down tilted x +0.0° y +0.0°, z down tilted x +3.0° " \
           "y +0.0°, z down tilted x -3.0° y +0.0°, z down tilted x +0.0° y +3.0° and 4 more)" \
           in line
    assert not out.exists()


def test_a_log_with_no_still_row_is_refused_for_that(tmp_path: Path) -> None:
    # Raw rows of a flight (40 mg of vibration throughout): no row is a still reading, and
    # the refusal says so rather than counting orientations in the vibration.
    t_us, acc = flight_samples(vibration_g=0.04)
    g = acc / 9.80665
    n = t_us.size
    src, out = tmp_path / "flight.csv", tmp_path / "model.json"
    write_recording(src, {"t_s": (t_us - t_us[0]) * 1e-6, "chamber_c": np.full(n, np.nan),
                          "ax": g[:, 0], "ay": g[:, 1], "az": g[:, 2], "n": np.ones(n)})
    r = subprocess.run([sys.executable, "-m", "service.cli", "calibrate", str(src), "-o",
                        str(out)], capture_output=True, text=True, cwd=Path(__file__).parents[2])
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "no still reading: every row was left out as taken while the sensor moved or " \
           "vibrated" in lines[0]
    assert "distinct orientation" not in lines[0]
    assert not out.exists()
