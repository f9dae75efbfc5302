"""``soakcal import`` of logs that keep the temperature: PX4 ULog, ArduPilot DataFlash, CSV,
OpenAXES with TEMP. The binary logs are built in the test (tests/calibration/log_writers.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from calibration import importers
from calibration.errors import RecordingError
from calibration.importers_cli import run_import
from calibration.recording import read_recording
from tests.calibration.log_writers import (
    flight_samples,
    warmup_samples,
    write_dataflash,
    write_dataflash_legacy,
    write_ulog,
)
from tests.realdata import need_realdata

G = 9.80665


def _args(fmt: str, src: Path, out: Path, **kw: object) -> argparse.Namespace:
    base = dict(format=fmt, raw=str(src), output=str(out), raw_samples=False,
                min_static_s=None, threshold=None, window_s=None, trim_s=None)
    base.update(kw)
    return argparse.Namespace(**base)


@pytest.mark.parametrize("fmt,writer", [("ulog", write_ulog), ("dataflash", write_dataflash)])
def test_flight_log_keeps_the_temperature_of_every_sample(tmp_path, capsys, fmt, writer):
    t_us, acc, temp = warmup_samples()
    src = writer(tmp_path / f"log.{fmt}", t_us, acc, temp)
    out = tmp_path / "rec.csv"
    assert run_import(_args(fmt, src, out)) == 0
    rec = read_recording(out)
    assert len(rec) == 400  # a warm-up is a time series: every sample is a row
    np.testing.assert_allclose(rec.columns["sensor_c"], temp, atol=1e-6)
    np.testing.assert_allclose(rec.raw_g, acc / G, atol=1e-6)
    np.testing.assert_allclose(rec.t_s[:3], [0.0, 0.02, 0.04], atol=1e-9)
    text = capsys.readouterr().out
    assert "temperature (sensor_c): 30.00 .. 40.00 °C, 400 of 400 samples" in text
    assert "wrote 400 raw sample rows" in text


@pytest.mark.parametrize("fmt,writer", [("ulog", write_ulog), ("dataflash", write_dataflash)])
def test_flight_log_without_temperature_says_so(tmp_path, capsys, fmt, writer):
    t_us, acc, _ = warmup_samples(n=100)
    src = writer(tmp_path / f"log.{fmt}", t_us, acc, None)
    out = tmp_path / "rec.csv"
    assert run_import(_args(fmt, src, out)) == 0
    text = capsys.readouterr().out
    expected = ("no sensor_accel temperature field; temperature left empty" if fmt == "ulog"
                else "no IMU T field")
    assert expected in text
    assert "temperature columns empty" in text
    assert not read_recording(out).has("sensor_c")


@pytest.mark.parametrize("fmt,writer", [("ulog", write_ulog), ("dataflash", write_dataflash)])
def test_flight_log_instance_is_chosen_and_a_missing_one_is_refused(tmp_path, capsys, fmt,
                                                                     writer):
    t_us, acc, temp = warmup_samples(n=50)
    src = writer(tmp_path / f"log.{fmt}", t_us, acc, temp, instances=2)
    raw = importers.read_source(fmt, src, instance=1)
    np.testing.assert_allclose(raw.acc_g[:, 0], (acc[:, 0] + 1.0) / G, atol=1e-6)
    out = tmp_path / "rec.csv"
    assert run_import(_args(fmt, src, out, instance=3)) == 2
    err = capsys.readouterr().err
    assert "instance" in err and "--instance N" in err
    assert err.count(str(src)) <= 1
    assert not out.exists()


@pytest.mark.parametrize("layout,temp_field,in_ms", [
    ("copter-3.3", "Temp", False), ("solo", "Temp", True), ("copter-3.2", None, True)])
def test_dataflash_older_imu_layouts_keep_time_and_temperature(tmp_path, capsys, layout,
                                                                temp_field, in_ms):
    # Real logs read this way: ArduCopter 3.3 and 3DR Solo call the temperature "Temp",
    # and logs before 3.3 (and Solo's) time IMU in ms; a 2014 ArduCopter 3.2 log ended
    # in a traceback (AttributeError: TimeUS) before.
    t_us, acc, temp = warmup_samples(n=200)
    src = write_dataflash_legacy(tmp_path / "old.bin", t_us, acc, temp, layout=layout)
    out = tmp_path / "rec.csv"
    assert run_import(_args("dataflash", src, out)) == 0
    rec = read_recording(out)
    assert len(rec) == 200
    np.testing.assert_allclose(rec.raw_g, acc / G, atol=1e-6)
    np.testing.assert_allclose(rec.t_s[:3], [0.0, 0.02, 0.04], atol=1e-9)
    text = capsys.readouterr().out
    assert ("IMU time read from TimeMS" in text) == in_ms
    if temp_field is None:
        assert "no IMU T field (nor Temp" in text
        assert not rec.has("sensor_c")
    else:
        assert f"IMU {temp_field} → sensor_c (°C)" in text
        np.testing.assert_allclose(rec.columns["sensor_c"], temp, atol=1e-5)
    second = importers.read_source("dataflash", src, instance=1)  # IMU2
    np.testing.assert_allclose(second.acc_g[:, 0], (acc[:, 0] + 1.0) / G, atol=1e-6)
    if temp_field is not None:
        np.testing.assert_allclose(second.temp_c, temp + 1.0, atol=1e-5)


def test_a_flight_log_is_said_to_have_no_still_part(tmp_path, capsys):
    # An ArduCopter 3.2 flight (TimeMS, no temperature) vibrating 40 mg rms per axis from
    # its first sample once read "static intervals: 1" against its own quietest decile.
    t_us, acc = flight_samples(vibration_g=0.04)
    src = write_dataflash_legacy(tmp_path / "flight.bin", t_us, acc, None, layout="copter-3.2")
    out = tmp_path / "rec.csv"
    assert run_import(_args("dataflash", src, out)) == 0
    assert len(read_recording(out)) == t_us.size  # the rows are written raw either way
    line = next(x for x in capsys.readouterr().out.splitlines()
                if x.startswith("static intervals"))
    assert line.startswith("static intervals: 0: no still part: the quietest 10 % of the log "
                           "scatters by ")
    mg = float(line.split("scatters by ")[1].split(" mg")[0])
    # 40 mg of white vibration at 50 Hz: its 0.1-s means scatter by 40/√5 ≈ 18 mg, the
    # sway by a few mg more; above the 10 mg ceiling either way
    assert 12.0 < mg < 25.0, line
    sample_mg = float(line.split("over 1-s windows (")[1].split(" mg")[0])
    assert 30.0 < sample_mg < 50.0  # the 40 mg of vibration, not a still sensor's noise
    assert "the log was recorded while the sensor moved or vibrated" in line


def test_a_still_log_imported_is_one_static_interval(tmp_path, capsys):
    t_us, acc, temp = warmup_samples(n=1000)
    src = write_dataflash(tmp_path / "bench.bin", t_us, acc, temp)
    assert run_import(_args("dataflash", src, tmp_path / "rec.csv")) == 0
    assert "static intervals: 1\n" in capsys.readouterr().out


def test_block_rows_average_samples_and_their_temperature(tmp_path, capsys):
    t_us, acc, temp = warmup_samples(n=400, rate_hz=50.0)
    src = write_ulog(tmp_path / "log.ulg", t_us, acc, temp)
    out = tmp_path / "rec.csv"
    assert run_import(_args("ulog", src, out, block_s=2.0)) == 0
    rec = read_recording(out)
    assert len(rec) == 4  # 8 s of samples in 2-s blocks
    np.testing.assert_allclose(rec.columns["n"], [100] * 4)
    np.testing.assert_allclose(rec.columns["sensor_c"], temp.reshape(4, 100).mean(axis=1),
                               atol=1e-6)
    np.testing.assert_allclose(rec.raw_g[:, 2], (acc[:, 2] / G).reshape(4, 100).mean(axis=1),
                               atol=1e-7)
    assert "wrote 4 rows (one per block)" in capsys.readouterr().out


def test_dataflash_says_when_the_autopilot_already_compensated(tmp_path):
    t_us, acc, temp = warmup_samples(n=20)
    src = write_dataflash(tmp_path / "log.bin", t_us, acc, temp,
                          params={"INS_TCAL1_ENABLE": 1.0, "INS_TCAL2_ENABLE": 0.0})
    raw = importers.read_source("dataflash", src)
    assert any("INS_TCAL1_ENABLE = 1 in this log" in n for n in raw.notes)


@pytest.mark.parametrize("fmt", ["ulog", "dataflash"])
def test_a_file_that_is_not_a_log_is_refused_with_its_kind(tmp_path, fmt):
    src = tmp_path / "x.bin"
    src.write_text("t_s,ax\n1,2\n")
    with pytest.raises(RecordingError,
                       match="not a readable|not an ArduPilot DataFlash|no sensor_accel"):
        importers.read_source(fmt, src)


# --- temperatures that are not readings ------------------------------------------
def _import_text(tmp_path: Path, capsys, fmt: str, writer, t_us, acc, temp) -> tuple[str, Path]:
    src = writer(tmp_path / f"log.{fmt}", t_us, acc, temp)
    out = tmp_path / "rec.csv"
    assert run_import(_args(fmt, src, out)) == 0
    return capsys.readouterr().out, out


@pytest.mark.parametrize("fmt,writer,channel", [("ulog", write_ulog, "sensor_accel temperature"),
                                                ("dataflash", write_dataflash, "IMU T")])
def test_a_simulators_zero_temperature_is_written_empty_and_said(tmp_path, capsys, fmt, writer,
                                                                  channel):
    """SITL logs carry 0.00 °C in every sample: not a reading, so no sensor_c, and the
    person reading the summary is told why and what calibrate will make of it."""
    t_us, acc, temp = warmup_samples(n=200)
    text, out = _import_text(tmp_path, capsys, fmt, writer, t_us, acc, np.zeros_like(temp))
    assert f"note: {channel} is exactly 0.00 °C in all 200 samples" in text
    assert "simulator (SITL)" in text
    assert "a warm-up calibration needs a measured temperature" in text
    assert "temperature columns empty" in text
    assert not read_recording(out).has("sensor_c")


@pytest.mark.parametrize("fmt,writer", [("ulog", write_ulog), ("dataflash", write_dataflash)])
def test_a_temperature_outside_a_dies_range_is_written_empty(tmp_path, capsys, fmt, writer):
    t_us, acc, temp = warmup_samples(n=100)
    text, out = _import_text(tmp_path, capsys, fmt, writer, t_us, acc, temp + 273.15)
    assert "outside a die's -60 .. 150 °C: not a die temperature" in text
    assert "temperature left empty" in text
    assert not read_recording(out).has("sensor_c")


@pytest.mark.parametrize("fmt,writer", [("ulog", write_ulog), ("dataflash", write_dataflash)])
def test_one_value_over_a_long_log_is_a_placeholder_but_a_short_one_is_kept(
        tmp_path, capsys, fmt, writer):
    t_us, acc, _ = warmup_samples(n=700, rate_hz=1.0)  # 699 s at 1 Hz
    text, out = _import_text(tmp_path, capsys, fmt, writer, t_us, acc, np.full(700, 25.0))
    assert "is 25 °C in all 700 samples over 699 s" in text and "placeholder" in text
    assert not read_recording(out).has("sensor_c")
    # The same value over 2 minutes may be a board at equilibrium: kept, nothing said.
    t_us, acc, _ = warmup_samples(n=120, rate_hz=1.0)
    (tmp_path / "short").mkdir()
    text, out = _import_text(tmp_path / "short", capsys, fmt, writer, t_us, acc,
                             np.full(120, 25.0))
    assert "placeholder" not in text and "temperature (sensor_c): 25.00 .. 25.00 °C" in text
    np.testing.assert_allclose(read_recording(out).columns["sensor_c"], 25.0)


def test_a_zero_temperature_column_in_a_csv_is_written_empty(tmp_path, capsys):
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az,temp_c",
                 ["0,0,0,1,0", "0.01,0,0,1,0.0", "0.02,0,0,1,0"])
    out = tmp_path / "rec.csv"
    assert run_import(_args("csv", src, out, accel_unit="g")) == 0
    text = capsys.readouterr().out
    assert "note: temperature column 'temp_c' is exactly 0.00 °C in all 3 samples" in text
    assert not read_recording(out).has("sensor_c")


# --- csv -------------------------------------------------------------------------
def _table(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def test_csv_with_column_map_and_units_converts_to_g_and_celsius(tmp_path, capsys):
    src = _table(tmp_path / "t.csv", "ms;X;Y;Z;TF",
                 ["0;0;0;1000;68", "10;0;0;1000;69.8", "20;2;0;1000;", "30;0;0;1000;71.6"])
    out = tmp_path / "rec.csv"
    args = _args("csv", src, out, columns="t=ms,ax=X,ay=Y,az=Z,temp=TF", accel_unit="mg",
                 temp_unit="F", time_unit="ms")
    assert run_import(args) == 0
    rec = read_recording(out)
    np.testing.assert_allclose(rec.t_s, [0.0, 0.01, 0.03])
    np.testing.assert_allclose(rec.raw_g[:, 2], [1.0, 1.0, 1.0])
    np.testing.assert_allclose(rec.columns["sensor_c"], [20.0, 21.0, 22.0])
    text = capsys.readouterr().out
    assert "temperature in °F → sensor_c (°C)" in text
    # the row without a temperature is dropped, not filled in
    assert "1 of 4 samples have no temperature: dropped" in text


def test_csv_without_a_header_row_is_read_by_column_position(tmp_path, capsys):
    """An inclinometer's log: ``id, ax, ay, az, T`` in mg and °C, 500 Hz, no header."""
    path = tmp_path / "t.csv"
    path.write_text("42652,21.9,21.7,1015.3,-18.176\n42652,13.5,16.7,1008.3,-18.236\n"
                    "42652,12.0,20.3,995.1,-18.236\n")
    out = tmp_path / "rec.csv"
    args = _args("csv", path, out, columns="ax=2,ay=3,az=4,temp=5", accel_unit="mg",
                 rate_hz=500.0)
    assert run_import(args) == 0
    rec = read_recording(out)
    assert len(rec) == 3  # the first line is data, not a header
    np.testing.assert_allclose(rec.raw_g[0], [0.0219, 0.0217, 1.0153])
    np.testing.assert_allclose(rec.t_s, [0.0, 0.002, 0.004])
    np.testing.assert_allclose(rec.columns["sensor_c"], [-18.176, -18.236, -18.236])
    assert "no header row: columns named by position 1..5" in capsys.readouterr().out
    # the default names do not exist in such a file: the refusal says to use positions
    assert run_import(_args("csv", path, tmp_path / "o2.csv", accel_unit="mg")) == 2
    err = capsys.readouterr().err
    assert "the file has no header row: name columns by position 1..5" in err


PUTTY_BANNER = "=~=~=~=~=~=~=~=~=~=~=~= PuTTY log 2026.05.08 15:24:01 =~=~=~=~=~=~=~=~=~=~=~="


def test_csv_skips_a_loggers_banner_and_a_row_cut_short(tmp_path, capsys):
    """A serial log saved by PuTTY: its banner line, then a row the capture caught
    mid-line (6 cells of 7), then ``temp_C, ax, ay, az, gx, gy, gz`` without a header."""
    path = tmp_path / "putty.csv"
    rows = [f"{49.35 - 0.01 * i:.6f},0.250,0.003,-0.032,0.31,-0.31,0.00" for i in range(5)]
    path.write_text("\n".join([PUTTY_BANNER, "0,0.003,-0.032,0.73,0.12,-1.10", *rows]) + "\n")
    out = tmp_path / "rec.csv"
    args = _args("csv", path, out, columns="ax=2,ay=3,az=4,temp=1", accel_unit="counts",
                 counts_per_g=0.25, rate_hz=50.0)
    assert run_import(args) == 0, capsys.readouterr().err
    rec = read_recording(out)
    assert len(rec) == 5  # the five full rows; neither skipped line is data
    np.testing.assert_allclose(rec.raw_g[0], [1.0, 0.012, -0.128])
    np.testing.assert_allclose(rec.columns["sensor_c"][[0, -1]], [49.35, 49.31])
    text = capsys.readouterr().out
    assert ("2 leading line(s) skipped before the table (not rows of it: a banner, or a row "
            "cut short; they begin '=~=~=~=~=~=~=~=~=~=~=~= ', '0,0.003,-0.032,0.73,0.12')"
            in text)
    assert "no header row: columns named by position 1..7" in text
    # a bad cell further down is named by its line in the file, banner counted
    bad = tmp_path / "bad.csv"
    bad.write_text(path.read_text().replace(rows[2], rows[2].replace("0.250", "0.2x0")))
    assert run_import(_args("csv", bad, tmp_path / "o2.csv", columns="ax=2,ay=3,az=4,temp=1",
                            accel_unit="counts", counts_per_g=0.25, rate_hz=50.0)) == 2
    assert "bad.csv:5:" in capsys.readouterr().err


def test_csv_a_header_that_does_not_line_up_is_not_skipped(tmp_path, capsys):
    # a header with text cells is never taken for a banner, even when the rows below it
    # have more cells: the row check refuses, naming the line, as for any such table
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az",
                 ["0,0,0,1,25", "0.01,0,0,1,25", "0.02,0,0,1,25"])
    assert run_import(_args("csv", src, tmp_path / "o.csv", accel_unit="g")) == 2
    err = capsys.readouterr().err
    assert "t.csv:2: has 5 cells, header has 4" in err


def test_csv_the_bmi270_putty_log_reads_past_its_banner(tmp_path, capsys):
    # The real BMI270 hot log (PuTTY; accel printed as g/4). Its banner and the row cut
    # short below it no longer stop the import: its first ten full rows are read...
    src = need_realdata("bmi270-ganesh/BMI_270_hot_test.csv")
    head = tmp_path / "head.csv"
    head.write_text("\n".join(src.read_text().splitlines()[:12]) + "\n")
    opts = dict(columns="ax=2,ay=3,az=4,temp=1", accel_unit="counts", counts_per_g=0.25,
                rate_hz=50.0)
    assert run_import(_args("csv", head, tmp_path / "head_rec.csv", **opts)) == 0
    rec = read_recording(tmp_path / "head_rec.csv")
    assert len(rec) == 10
    assert np.all(np.abs(np.linalg.norm(rec.raw_g, axis=1) - 1.0) < 0.02)
    assert "2 leading line(s) skipped before the table" in capsys.readouterr().out
    # ...and the whole file stops where its table breaks: line 13 holds two rows run
    # together (8 cells), said with its line number, not at the banner
    assert run_import(_args("csv", src, tmp_path / "rec.csv", **opts)) == 2
    err = capsys.readouterr().err
    assert "BMI_270_hot_test.csv:13: has 8 cells" in err
    assert "--bad-lines skip leaves such lines out" in err
    # --bad-lines skip: the garbled line and the one cut short at the end are left out,
    # each named; every other row is kept
    assert run_import(_args("csv", src, tmp_path / "rec.csv", bad_lines="skip", **opts)) == 0
    out = capsys.readouterr().out
    assert ("2 line(s) not rows of the table left out (--bad-lines skip), 6533 rows kept "
            "(without a time column" in out)
    assert "line 13: has 8 cells, header has 7; line 6537: has 1 cells, header has 7" in out
    assert len(read_recording(tmp_path / "rec.csv")) == 6533


def test_csv_bad_lines_skip_is_for_a_few_lines_not_a_misread_table(tmp_path, capsys):
    rows = [f"{0.01 * i:.2f},0,0,1,25" for i in range(300)]
    rows[7] = "0.07,0,0x,1,25"  # a cell that is not a number, left out and named
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az,temp_c", rows)
    out = tmp_path / "o.csv"
    assert run_import(_args("csv", src, out, accel_unit="g", bad_lines="skip")) == 0
    text = capsys.readouterr().out
    assert ("1 line(s) not rows of the table left out (--bad-lines skip), 299 rows kept: "
            "line 9 column 'ay': not a number: '0x'") in text
    assert len(read_recording(out)) == 299
    # four bad lines of 300 (> 1 %): the table itself is misread, refused with the fix
    for i in (20, 40, 60):
        rows[i] = rows[i] + ",9"
    src = _table(tmp_path / "t2.csv", "t_s,ax,ay,az,temp_c", rows)
    assert run_import(_args("csv", src, tmp_path / "o2.csv", accel_unit="g",
                            bad_lines="skip")) == 2
    err = capsys.readouterr().err
    assert ("t2.csv:9: column 'ay': not a number: '0x'; 4 of 300 lines are not rows of the "
            "table, more than the 1% --bad-lines skip leaves out: check --delimiter and "
            "--columns") in err
    assert not (tmp_path / "o2.csv").exists()


def test_csv_counts_and_kelvin(tmp_path):
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az,temp_c",
                 ["0,100,-50,16484,300.15", "0.01,100,-50,16484,301.15"])
    from calibration.importers_table import TableUnits

    raw = importers.read_source("csv", src, units=TableUnits(
        accel="counts", counts_per_g=16384.0, offset_counts=100.0, temp="K"))
    np.testing.assert_allclose(raw.acc_g[0], [0.0, -150 / 16384, 1.0])
    np.testing.assert_allclose(raw.temp_c, [27.0, 28.0])


def test_csv_refuses_a_wrong_unit_and_names_the_likely_one(tmp_path, capsys):
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az,temp_c",
                 ["0,0,0,9.81,25", "0.01,0,0,9.80,25"])
    out = tmp_path / "rec.csv"
    assert run_import(_args("csv", src, out, accel_unit="g")) == 2
    err = capsys.readouterr().err.strip()
    assert "median |a| is 9.805 g, not about 1 g; it looks like m/s²" in err
    assert "--accel-unit" in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_csv_a_reading_scaled_for_another_range_is_named(tmp_path, capsys):
    # A firmware that sets ±8 g and divides counts by the ±2 g 16384 LSB/g prints a quarter
    # of the acceleration (the BMI270 log's case); the refusal says how to read it.
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az,temp_c",
                 ["0,0,0.003,0.2505,25", "0.01,0,0.003,0.2502,25"])
    assert run_import(_args("csv", src, tmp_path / "o.csv", accel_unit="g")) == 2
    err = capsys.readouterr().err
    assert ("median |a| is 0.2504 g, not about 1 g; ×4 it is 1.001 g: read with the "
            "sensitivity of another full-scale range? (as --accel-unit counts: "
            "--counts-per-g 0.25)") in err
    # 0.7 g is no power of two from 1 g within 5 %: no such guess
    src = _table(tmp_path / "t3.csv", "t_s,ax,ay,az,temp_c", ["0,0,0,0.35,25", "0.01,0,0,0.35,25"])
    assert run_import(_args("csv", src, tmp_path / "o3.csv", accel_unit="g")) == 2
    assert "full-scale range" not in capsys.readouterr().err


def test_csv_refuses_kelvin_read_as_celsius(tmp_path, capsys):
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az,temp_c",
                 ["0,0,0,1,298.1", "0.01,0,0,1,298.2"])
    out = tmp_path / "rec.csv"
    assert run_import(_args("csv", src, out, accel_unit="g")) == 2
    err = capsys.readouterr().err
    assert "it looks like kelvin" in err and "--temp-unit" in err


def test_csv_needs_an_accel_unit_and_says_which(tmp_path, capsys):
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az", ["0,0,0,1"])
    assert run_import(_args("csv", src, tmp_path / "o.csv")) == 2
    err = capsys.readouterr().err
    assert "give --accel-unit (g, mg, m/s2, counts)" in err


def test_csv_without_temperature_column_says_so(tmp_path, capsys):
    src = _table(tmp_path / "t.csv", "t_s,ax,ay,az", ["0,0,0,1", "0.01,0,0,1"])
    assert run_import(_args("csv", src, tmp_path / "o.csv", accel_unit="g")) == 0
    assert "no temperature column 'temp_c' (--columns temp=NAME); temperature left empty" in (
        capsys.readouterr().out)


# --- openaxes TEMP ---------------------------------------------------------------
def _openaxes(path: Path, with_temp: bool) -> Path:
    head = "MAC;IMU;TIME;INDEX;ACCEL_ADXL355_0;ACCEL_ADXL355_1;ACCEL_ADXL355_2"
    head += ";TEMP" if with_temp else ""
    rows = []
    for i in range(600):
        row = f"aa;imu9;{1_000_000 + i * 10_000};{i};0.0;0.0;9.80665"
        rows.append(row + (f";{512 * 2 + i // 300}" if with_temp else ""))
    return _table(path, head, rows)


def test_openaxes_temp_kept_only_with_its_conversion(tmp_path):
    src = _openaxes(tmp_path / "oa.csv", with_temp=True)
    raw = importers.read_source("openaxes", src)
    assert raw.temp_c is None
    assert any("TEMP column present but its unit is undocumented" in n for n in raw.notes)
    raw = importers.read_source("openaxes", src, temp_c_per_count=1 / 512, temp_offset_c=23.0)
    np.testing.assert_allclose(raw.temp_c[[0, 599]], [25.0, 25.0 + 1 / 512])


def test_openaxes_without_temp_names_what_is_missing(tmp_path):
    raw = importers.read_source("openaxes", _openaxes(tmp_path / "oa.csv", with_temp=False))
    assert any("no TEMP column" in n for n in raw.notes)


def test_the_command_line_wiring_reaches_the_table_reader(tmp_path, capsys):
    """`soakcal import` as typed: every csv flag arrives where the reader needs it."""
    from service.cli import main

    src = _table(tmp_path / "t.txt", "time\tA\tB\tC\tDIE",
                 ["0\t0\t0\t4096\t3000", "500\t4\t0\t4096\t3512", "1000\t0\t0\t4096\t4024"])
    out = tmp_path / "rec.csv"
    code = main(["import", "--format", "csv", str(src), "-o", str(out),
                 "--columns", "t=time,ax=A,ay=B,az=C,temp=DIE", "--delimiter", "tab",
                 "--accel-unit", "counts", "--counts-per-g", "4096",
                 "--temp-unit", "counts", "--temp-c-per-count", "0.001953125",
                 "--temp-offset-c", "23", "--time-unit", "ms"])
    assert code == 0, capsys.readouterr().err
    rec = read_recording(out)
    np.testing.assert_allclose(rec.t_s, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(rec.raw_g[1], [4 / 4096, 0.0, 1.0])
    np.testing.assert_allclose(rec.columns["sensor_c"], [23 + 3000 / 512, 23 + 3512 / 512,
                                                         23 + 4024 / 512])


def test_the_command_line_instance_and_block_flags_reach_the_log_readers(tmp_path):
    from service.cli import main

    t_us, acc, temp = warmup_samples(n=200)
    src = write_dataflash(tmp_path / "log.bin", t_us, acc, temp, instances=2)
    out = tmp_path / "rec.csv"
    assert main(["import", "--format", "dataflash", str(src), "-o", str(out),
                 "--instance", "1", "--block-s", "1"]) == 0
    rec = read_recording(out)
    assert len(rec) == 4
    np.testing.assert_allclose(rec.raw_g[0, 0], (acc[:50, 0].mean() + 1.0) / G, atol=1e-6)


def test_warmup_noise_is_not_the_drift(tmp_path, capsys):
    """A 70-s warm-up drifts 20 mg on z with 100 µg noise: the summary's noise is ~100 µg."""
    t_us, acc, temp = warmup_samples(n=3500)
    src = write_ulog(tmp_path / "log.ulg", t_us, acc, temp)
    assert run_import(_args("ulog", src, tmp_path / "rec.csv")) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "noise per sample" in x)
    assert "successive differences" in line
    z_ug = float(line.split(" z ")[1])
    assert 85.0 < z_ug < 115.0


def test_the_peer_benchmark_reads_a_log_through_the_import_and_says_why_not(tmp_path):
    """bench_warmup_peers --log: a SITL log is not compared (the import's note says why);
    a real-looking warm-up comes back with every sample and its temperature."""
    from benchmarks.bench_warmup_peers import imported_log

    t_us, acc, temp = warmup_samples(n=2500)  # 50 s at 50 Hz: 2 held-out 10-s blocks
    sitl = write_ulog(tmp_path / "sitl.ulg", t_us, acc, np.zeros_like(temp))
    log, why = imported_log(sitl, "ulog", [], tmp_path)
    assert log is None and "exactly 0.00 °C" in why and "measured temperature" in why
    warm = write_ulog(tmp_path / "warm.ulg", t_us, acc, temp)
    log, _ = imported_log(warm, "ulog", [], tmp_path)
    assert log is not None and log.t_s.size == 2500
    np.testing.assert_allclose(log.temp_c, temp, atol=1e-6)
    np.testing.assert_allclose(log.acc_g, acc / G, atol=1e-6)


@pytest.mark.parametrize(("accel_id", "says"), [
    # bus ids as ArduPilot builds them: devtype << 16 | address << 8 | bus << 3 | bus type
    ((0x34 << 16) | (0x00 << 8) | (1 << 3) | 2,
     "INS_ACC_ID 3407882 is an ICM-42688 (AP_InertialSensor_Invensensev3: its temperature "
     "unfiltered): export its ArduPilot file with --temperature-reading per-sample"),
    ((0x13 << 16) | (0x00 << 8) | (4 << 3) | 2,
     "is an MPU-6000/6500 or ICM-20608 (AP_InertialSensor_Invensense: its temperature "
     "through a 2-pole 1-Hz low-pass): export its ArduPilot file with "
     "--temperature-reading filtered"),
    ((0x38 << 16) | (0x00 << 8) | (1 << 3) | 2,
     "is device type 0x38: soakcal does not know whether its ArduPilot driver filters"),
])
def test_dataflash_names_the_reading_the_boards_driver_hands_the_compensation(
        tmp_path, accel_id, says):
    t_us, acc, temp = warmup_samples(n=20)
    src = write_dataflash(tmp_path / "log.bin", t_us, acc, temp,
                          params={"INS_ACC_ID": float(accel_id), "INS_ACC2_ID": 0.0})
    raw = importers.read_source("dataflash", src)
    assert sum(says in n for n in raw.notes) == 1, raw.notes


def test_dataflash_without_a_device_id_says_nothing_of_the_driver(tmp_path):
    t_us, acc, temp = warmup_samples(n=20)
    src = write_dataflash(tmp_path / "log.bin", t_us, acc, temp, params={"INS_ACC2_ID": 5.0})
    raw = importers.read_source("dataflash", src)
    assert not any("_ID" in n or "--temperature-reading" in n for n in raw.notes)
