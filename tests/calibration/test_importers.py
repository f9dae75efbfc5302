"""Importers of other labs' static recordings, the static-interval detector, ``soakcal import``."""

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from calibration import importers
from calibration.errors import RecordingError
from calibration.fit import fit_norm
from calibration.importers_cli import run_import
from calibration.recording import read_recording
from tests.calibration.log_writers import flight_samples
from tests.realdata import need_realdata

OPENAXES = "openaxes-adxl355/log_imu9_2022-06-22_22-13-55.csv"


# --- synthetic signal: rest, then moves between static positions ---------------
def _synthetic(seed: int = 0, rate_hz: float = 100.0):
    """10 s rest, then 3 positions of 4, 3, 1 s separated by 1.5 s moves; noise 1 mg."""
    rng = np.random.default_rng(seed)
    plan = [(10.0, (0, 0, 1)), (1.5, None), (4.0, (1, 0, 0)), (1.5, None),
            (3.0, (0, -1, 0)), (1.5, None), (1.0, (0, 0, -1)), (1.5, None)]
    t, acc, truth = [], [], []
    t0 = 0.0
    for dur, g in plan:
        n = int(round(dur * rate_hz))
        tt = t0 + np.arange(n) / rate_hz
        if g is None:  # a hand move: large, smooth swing
            a = np.column_stack([np.sin(5 * tt), np.cos(4 * tt), np.sin(3 * tt)]) * 0.7
        else:
            a = np.tile(g, (n, 1)).astype(float)
            truth.append((tt[0], tt[-1]))
        t.append(tt)
        acc.append(a + rng.normal(0, 1e-3, (n, 3)))
        t0 += dur
    return np.concatenate(t), np.vstack(acc), truth


def test_moving_variance_matches_a_direct_computation() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(0, 1, (200, 3)) + 5.0
    v = importers.moving_variance(x, 21)
    for i in (0, 5, 50, 199):
        lo, hi = max(i - 10, 0), min(i + 11, 200)
        np.testing.assert_allclose(v[i], x[lo:hi].var(axis=0), rtol=1e-9)


def test_detector_finds_the_static_positions_and_drops_short_ones() -> None:
    t, acc, truth = _synthetic()
    iv = importers.detect_static_intervals(
        t, acc, window_s=0.5, threshold=6.0, min_duration_s=2.0, init_rest_s=8.0)
    assert len(iv) == 3  # rest + 4 s + 3 s; the 1 s position is shorter than 2 s
    for (s, e), (ts, te) in zip(iv, truth[:3], strict=True):
        assert ts - 0.05 <= t[s] <= ts + 0.5  # never starts inside the move
        assert te - 0.5 <= t[e - 1] <= te + 0.05
    iv_all = importers.detect_static_intervals(
        t, acc, window_s=0.5, threshold=6.0, min_duration_s=0.3, init_rest_s=8.0)
    assert len(iv_all) == 4  # the 1 s position, less half a window at each end


def test_trim_cuts_both_edges() -> None:
    t, acc, _ = _synthetic()
    kw = dict(window_s=0.5, threshold=6.0, min_duration_s=2.0, init_rest_s=8.0)
    raw_iv = importers.detect_static_intervals(t, acc, **kw)
    cut_iv = importers.detect_static_intervals(t, acc, trim_s=0.5, **kw)
    for (s, e), (cs, ce) in zip(raw_iv, cut_iv, strict=True):
        assert t[cs] - t[s] == pytest.approx(0.5, abs=0.011)
        assert t[e - 1] - t[ce - 1] == pytest.approx(0.5, abs=0.011)


def test_threshold_is_relative_to_the_initial_rest() -> None:
    t, acc, _ = _synthetic()
    kw = dict(window_s=0.5, min_duration_s=2.0, init_rest_s=8.0)
    # The same record, 5× noisier everywhere (still under what a still accelerometer
    # scatters, importers.STILL_NOISE_CEILING_G): the same intervals (relative threshold).
    loud = acc + np.random.default_rng(3).normal(0, 5e-3, acc.shape)
    a = importers.detect_static_intervals(t, acc, threshold=6.0, **kw)
    b = importers.detect_static_intervals(t, loud, threshold=6.0, **kw)
    assert len(a) == len(b) == 3
    # A threshold below 1 × rest variance finds (almost) nothing static.
    assert len(importers.detect_static_intervals(t, acc, threshold=0.3, **kw)) == 0


def test_a_log_vibrating_from_its_first_sample_has_no_static_interval() -> None:
    # A flight: 40 mg rms of motor vibration from the first sample. Against its own
    # quietest decile it once read as one 118-s "static interval".
    t_us, acc = flight_samples(vibration_g=0.04)
    t, a = (t_us - t_us[0]) * 1e-6, acc / 9.80665
    kw = dict(window_s=1.0, threshold=6.0, min_duration_s=5.0, trim_s=0.5)
    assert importers.detect_static_intervals(t, a, **kw) == []
    assert len(importers.detect_static_intervals(t, a, ceiling_g=None, **kw)) >= 1
    # A board lying still for as long (1 mg: the quietest decile is a rest) is one interval.
    still = np.array([0.0, 0.0, -1.0]) + np.random.default_rng(4).normal(0, 1e-3, a.shape)
    iv = importers.detect_static_intervals(t, still, **kw)
    assert len(iv) == 1 and t[iv[0][1] - 1] - t[iv[0][0]] > 110.0


def test_a_short_still_stretch_before_a_flight_is_found() -> None:
    # 8 s on the ground (7 % of the log, under the quietest decile) and then flying.
    t_us, acc = flight_samples(vibration_g=0.04, still_s=8.0)
    t, a = (t_us - t_us[0]) * 1e-6, acc / 9.80665
    iv = importers.detect_static_intervals(t, a, window_s=1.0, threshold=6.0,
                                           min_duration_s=5.0, trim_s=0.5)
    assert len(iv) == 1
    s, e = iv[0]
    assert t[s] < 1.0 and 6.5 < t[e - 1] < 8.0


def test_detector_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="expected"):
        importers.detect_static_intervals(np.arange(10.0), np.zeros((10, 2)),
                                          window_s=1, threshold=5, min_duration_s=1)
    with pytest.raises(ValueError):
        importers.detect_static_intervals(np.arange(10.0), np.zeros((10, 3)),
                                          window_s=0, threshold=5, min_duration_s=1)


def test_intervals_average_to_v1_rows_with_empty_temperature() -> None:
    t, acc, _ = _synthetic()
    raw = importers.RawImport("mem", "test", t, acc, init_rest_s=8.0)
    iv = importers.detect_static_intervals(t, acc, window_s=0.5, threshold=6.0,
                                           min_duration_s=2.0, init_rest_s=8.0, trim_s=0.5)
    rec = importers.intervals_to_recording(raw, iv)
    assert len(rec) == 3
    np.testing.assert_allclose(rec.raw_g, [[0, 0, 1], [1, 0, 0], [0, -1, 0]], atol=1e-3)
    assert np.all(np.isnan(rec.columns["chamber_c"])) and not rec.has_temperature
    np.testing.assert_allclose(rec.columns["sd_x"], 1e-3, rtol=0.15)
    assert list(rec.columns["position"]) == [0, 1, 2]
    s, e = iv[1]
    assert rec.columns["n"][1] == e - s
    assert rec.t_s[1] == pytest.approx(0.5 * (t[s] + t[e - 1]))


# --- readers on small synthetic files -------------------------------------------
OA_HEADER = ("MAC;IMU;TIME;INDEX;QUATERNION_0;QUATERNION_1;QUATERNION_2;QUATERNION_3;"
             "ACCEL_ADXL355_0;ACCEL_ADXL355_1;ACCEL_ADXL355_2;ACCEL_BMI160_0;ACCEL_BMI160_1;"
             "ACCEL_BMI160_2;GYRO_0;GYRO_1;GYRO_2;GYRO_ECC_0;GYRO_ECC_1;GYRO_ECC_2")


def _oa_line(t_us: int, adxl: str = "0.0;9.80665;0.0") -> str:
    return f"AA:BB;imu9;{t_us};1;0;0;0;0;{adxl};0.1;9.7;0.2;0;0;0;0;0;0"


def test_openaxes_reader_converts_m_s2_to_g_and_picks_the_sensor(tmp_path: Path) -> None:
    f = tmp_path / "oa.csv"
    f.write_text("\n".join([OA_HEADER, _oa_line(1_000_000), _oa_line(1_010_000)]) + "\n")
    raw = importers.read_openaxes(f)
    np.testing.assert_allclose(raw.t_s, [0.0, 0.01])
    np.testing.assert_allclose(raw.acc_g[0], [0.0, 1.0, 0.0])
    bmi = importers.read_openaxes(f, sensor="bmi160")
    np.testing.assert_allclose(bmi.acc_g[0], np.array([0.1, 9.7, 0.2]) / 9.80665)
    with pytest.raises(RecordingError, match="sensor"):
        importers.read_openaxes(f, sensor="lsm6")


def test_openaxes_errors_name_line_and_column(tmp_path: Path) -> None:
    f = tmp_path / "oa.csv"
    f.write_text("\n".join([OA_HEADER, _oa_line(1_000_000), _oa_line(1_010_000, "0;x;0")]))
    with pytest.raises(RecordingError) as info:
        importers.read_openaxes(f)
    assert (info.value.line, info.value.column) == (3, "ACCEL_ADXL355_1")
    f.write_text("\n".join([OA_HEADER, _oa_line(2_000_000), _oa_line(1_000_000)]))
    with pytest.raises(RecordingError) as info:
        importers.read_openaxes(f)
    assert (info.value.line, info.value.column) == (3, "TIME")
    f.write_text(OA_HEADER.replace("ACCEL_ADXL355_2", "ACCEL_Z") + "\n" + _oa_line(1))
    with pytest.raises(RecordingError) as info:
        importers.read_openaxes(f)
    assert (info.value.line, info.value.column) == (1, "ACCEL_ADXL355_2")


def test_imu_tk_reader_counts_and_options(tmp_path: Path) -> None:
    f = tmp_path / "acc.mat"
    f.write_text("   1.0e-02   3.3123e+04   3.3276e+04   3.6430e+04\n"
                 "   2.0e-02   3.3123e+04   3.3276e+04   3.6430e+04\n")
    raw = importers.read_imu_tk(f)  # Xsens factory offsets, 415 counts per m/s²
    np.testing.assert_allclose(raw.acc_g[0], [0, 0, (36430 - 32360) / (415 * 9.80665)])
    np.testing.assert_allclose(raw.t_s, [0.0, 0.01])
    raw2 = importers.read_imu_tk(f, counts_per_g=3700.0, offset_counts=32768)
    np.testing.assert_allclose(raw2.acc_g[0], np.array([355, 508, 3662]) / 3700.0)
    f.write_text("1.0 2.0 3.0\n")
    with pytest.raises(RecordingError) as info:
        importers.read_imu_tk(f)
    assert info.value.line == 1 and "4 columns" in str(info.value)
    f.write_text("1 2 3 4\n2 2 z 4\n")
    with pytest.raises(RecordingError) as info:
        importers.read_imu_tk(f)
    assert (info.value.line, info.value.column) == (2, "ay")


def test_mpu6050_reader_preamble_and_scale(tmp_path: Path) -> None:
    f = tmp_path / "mpu.csv"
    f.write_text("Fs,50\nLogging Type,0\nInitialization time,2.5\nWaiting time,3\n"
                 "ax,ay,az,gx,gy,gz\n0,0,16384,1,2,3\n-16384,0,0,1,2,3\n")
    raw = importers.read_mpu6050(f)
    np.testing.assert_allclose(raw.acc_g, [[0, 0, 1], [-1, 0, 0]])
    np.testing.assert_allclose(raw.t_s, [0.0, 0.02])
    assert raw.init_rest_s == 2.5
    f.write_text("Fs,50\nLogging Type,0\nInitialization time,-1\nWaiting time,3\n"
                 "ax,ay,az,gx,gy,gz\n0,0,16384,1,2,3\n0,0.5.1,0,1,2,3\n")
    with pytest.raises(RecordingError) as info:
        importers.read_mpu6050(f)
    assert (info.value.line, info.value.column) == (7, "ay")
    f.write_text("Fs,0\nLogging Type,0\nInitialization time,-1\nWaiting time,3\nax,ay,az\n1,2,3\n")
    with pytest.raises(RecordingError, match="Fs"):
        importers.read_mpu6050(f)


def test_ferraris_session_and_list(tmp_path: Path) -> None:
    n = 600
    acc = np.zeros((n, 3))
    parts = {"x_p": (0, 1), "x_a": (0, -1), "y_p": (1, 1), "y_a": (1, -1),
             "z_p": (2, 1), "z_a": (2, -1)}
    spec = {}
    for k, (name, (axis, sign)) in enumerate(parts.items()):
        acc[k * 100:(k + 1) * 100, axis] = sign * 9.80665
        spec[name] = {"start": k * 100 + 10, "end": k * 100 + 90}
    spec["x_rot"] = {"start": 0, "end": 5}
    lines = ["n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z"]
    lines += [f"{i},0,0,0,{a[0]},{a[1]},{a[2]}" for i, a in enumerate(acc)]
    f = tmp_path / "sess.csv"
    f.write_text("\n".join(lines) + "\n")
    (tmp_path / "sess_list.json").write_text(json.dumps(spec))
    raw = importers.read_ferraris(f)
    rec = importers.intervals_to_recording(raw, importers.find_intervals(
        raw, importers.DetectorSettings(trim_s=0.0)))
    assert len(rec) == 6
    np.testing.assert_allclose(rec.raw_g, rec.ref_g, atol=1e-12)
    assert list(rec.columns["n"]) == [80] * 6
    # The sections are hand-placed: the import says so (calibration/placement.py).
    assert list(rec.columns["ref_tol_deg"]) == [2.0] * 6
    del spec["z_a"]
    (tmp_path / "sess_list.json").write_text(json.dumps(spec))
    with pytest.raises(RecordingError) as info:
        importers.read_ferraris(f)
    assert info.value.column == "z_a"


def test_ferraris_annotated(tmp_path: Path) -> None:
    lines = ["part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z"]
    for name, g in importers.FERRARIS_STATIC_PARTS.items():
        c = (np.array(g) * 2048).astype(int)
        lines += [f"{name},{i},{c[0]},{c[1]},{c[2]},0,0,0" for i in range(50)]
    lines += [f"x_rot,{i},0,0,2048,0,0,900" for i in range(50)]
    f = tmp_path / "ann.csv"
    f.write_text("\n".join(lines) + "\n")
    raw = importers.read_ferraris(f)
    rec = importers.intervals_to_recording(raw, raw.sections)
    np.testing.assert_allclose(rec.raw_g, rec.ref_g)
    lines[5] = "x_p,4,0,oops,0,0,0,0"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError) as info:
        importers.read_ferraris(f)
    assert (info.value.line, info.value.column) == (6, "acc_y")


def test_unknown_format_and_missing_file() -> None:
    with pytest.raises(RecordingError, match="unknown import format"):
        importers.read_source("xls", "x.xls")
    with pytest.raises(RecordingError, match="not found"):
        importers.read_source("imu_tk", "/nonexistent/acc.mat")


# --- the CLI entry -----------------------------------------------------------------
def _ns(fmt: str, src: Path, out: Path, **kw: object) -> argparse.Namespace:
    base = dict(format=fmt, raw_path=str(src), output=str(out), min_static_s=None,
                threshold=None, raw=False)
    base.update(kw)
    return argparse.Namespace(**base)


def _mpu_file(tmp_path: Path) -> Path:
    """MPU-6050 format: 3 s rest, 3 positions of 2 s, moves of 1 s, 100 Hz."""
    t, acc, _ = _synthetic(seed=4)
    counts = np.round(acc * 16384).astype(int)
    f = tmp_path / "mpu.csv"
    f.write_text("Fs,100\nLogging Type,0\nInitialization time,8\nWaiting time,3\n"
                 "ax,ay,az,gx,gy,gz\n"
                 + "\n".join(f"{a},{b},{c},0,0,0" for a, b, c in counts) + "\n")
    return f


def test_run_import_writes_a_readable_recording(tmp_path: Path, capsys) -> None:
    out = tmp_path / "rec.csv"
    assert run_import(_ns("mpu6050", _mpu_file(tmp_path), out)) == 0
    rec = read_recording(out)
    assert len(rec) == 3 and "chamber_c" in rec.header and not rec.has_temperature
    text = capsys.readouterr().out
    assert "static intervals: 3" in text and "µg" in text and "|g|" in text
    # what the file holds but the import did not read is named, not silently dropped
    assert "note: gx, gy, gz (the gyroscope) not read" in text
    assert "note: this MPU-6050 CSV has no temperature column; temperature left empty" in text


def test_run_import_of_a_position_file_that_never_holds_still_is_refused_with_why(
        tmp_path: Path, capsys) -> None:
    # An MPU-6050 file shaken throughout (30 mg rms per axis): there is no position to
    # average, and the line says why instead of "no static interval found" alone.
    t_us, acc = flight_samples(seconds=60.0, rate_hz=100.0, vibration_g=0.03)
    counts = np.round(acc / 9.80665 * 16384).astype(int)
    f = tmp_path / "shaken.csv"
    f.write_text("Fs,100\nLogging Type,0\nInitialization time,8\nWaiting time,3\n"
                 "ax,ay,az,gx,gy,gz\n"
                 + "\n".join(f"{a},{b},{c},0,0,0" for a, b, c in counts) + "\n")
    out = tmp_path / "rec.csv"
    assert run_import(_ns("mpu6050", f, out)) == 2
    err = capsys.readouterr().err
    assert "no static interval found: no still part: the initial rest of the log" in err
    assert "above the 10 mg a still accelerometer's noise reaches" in err
    assert not out.exists()


def test_run_import_raw_writes_one_row_per_sample(tmp_path: Path) -> None:
    out = tmp_path / "raw.csv"
    src = _mpu_file(tmp_path)
    assert run_import(_ns("mpu6050", src, out, raw=True)) == 0
    rec = read_recording(out)
    assert len(rec) == len(src.read_text().splitlines()) - 5
    assert np.all(rec.columns["n"] == 1)


def test_run_import_options_change_the_intervals(tmp_path: Path) -> None:
    out = tmp_path / "rec.csv"
    assert run_import(_ns("mpu6050", _mpu_file(tmp_path), out, min_static_s=5.0)) == 0
    assert len(read_recording(out)) == 1  # only the 10 s initial rest is that long


@pytest.mark.parametrize("bad", ["format", "content", "option", "missing"])
def test_run_import_bad_input_exits_2_and_writes_nothing(tmp_path: Path, capsys,
                                                         bad: str) -> None:
    src = _mpu_file(tmp_path)
    out = tmp_path / "out" / "rec.csv"
    kw: dict[str, object] = {}
    fmt = "mpu6050"
    if bad == "format":
        fmt = "excel"
    elif bad == "content":
        src.write_text(src.read_text().replace("\n0,", "\n0,x", 1))
    elif bad == "option":
        kw["threshold"] = -3.0
    else:
        src = tmp_path / "nope.csv"
    assert run_import(_ns(fmt, src, out, **kw)) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "error" in err
    assert not out.exists()


# --- real recordings (excerpts, and one whole-file figure) ---------------------------
def _excerpt(src: Path, dst: Path, n_lines: int) -> Path:
    with src.open(encoding="utf-8") as fh:
        dst.write_text("".join(next(fh) for _ in range(n_lines)))
    return dst


@pytest.mark.parametrize(("reader", "rel", "n", "g_range"), [
    (importers.read_openaxes, OPENAXES, 300,
     (1.01, 1.06)),  # ~3 % nominal-scale error on this ADXL355 (README: 10.07-10.26 m/s²)
    (importers.read_imu_tk, "imu_tk-xsens/xsens_acc.mat", 300, (0.98, 1.02)),
    (importers.read_mpu6050, "tomisuarez2-mpu6050/example_data_calibration.csv", 300,
     (0.85, 1.15)),
], ids=["openaxes", "imu_tk", "mpu6050"])
def test_real_excerpts_parse_to_one_g_at_rest(tmp_path: Path, reader, rel: str, n: int,
                                              g_range: tuple[float, float]) -> None:
    src = need_realdata(rel)
    raw = reader(_excerpt(src, tmp_path / Path(rel).name, n))
    g = np.linalg.norm(raw.acc_g.mean(axis=0))
    lo, hi = g_range
    assert lo < g < hi, (rel, g)
    assert np.all(np.diff(raw.t_s) > 0) and raw.t_s[0] == 0.0


def test_real_ferraris_files_give_six_labelled_positions() -> None:
    for name in ("example_ferraris_session.csv", "annotated_session.csv"):
        src = need_realdata(f"imucal-ferraris/{name}")
        _, iv, rec = importers.import_static("ferraris", src)
        assert len(rec) == 6
        # Each section reads ~±1 g along its labelled axis (uncalibrated: within 8 %).
        along = np.sum(rec.raw_g * rec.ref_g, axis=1)
        assert np.all(np.abs(along - 1.0) < 0.08), along


def test_openaxes_norm_fit_reaches_0_30_mg() -> None:
    _, iv, rec = importers.import_static("openaxes", need_realdata(OPENAXES))
    assert 30 <= len(iv) <= 40  # README: 33 at 5×, 38 at 10× (plus the initial rest)
    for sigma in (None, rec.sigma_g):
        res = fit_norm(rec.raw_g, sigma)
        assert res.rmse_norm_before_ug > 30_000  # README: 36 mg at nominal scale
        assert res.rmse_norm_ug <= 300.0, res.rmse_norm_ug
