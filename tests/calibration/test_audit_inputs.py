"""Wrong inputs a lab engineer might give (issue 20, docs/benchmarks.md "Wrong inputs a lab
engineer might give"): each is refused with its own cause and fix, never fitted into a model.

Every input is built here: a 500 Hz one-orientation warm-up like the inclinometer log of
the audit (z up, 7/6/18 mg of sample noise, the die warming by a few °C), written with one
mistake."""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calibration import cli
from calibration.importers_cli import run_import
from calibration.recording import write_recording
from simulators.warmup_log import warmup_log

RATE_HZ = 500.0


def _warmup(n: int = 6000, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) acceleration in mg and (n,) die temperature in °C (0.06 °C codes)."""
    rng = np.random.default_rng(seed)
    temp = np.round((-18.7 + 5.4 * np.arange(n) / n) / 0.0604) * 0.0604
    acc = np.column_stack([15.0 + rng.normal(0, 7, n), 18.0 + rng.normal(0, 6, n),
                           1008.0 + 2.8 * (temp + 16.0) + rng.normal(0, 18, n)])
    return acc, temp


def _write(path: Path, rows: np.ndarray, header: str | None = None, fmt: str = "%.4f") -> Path:
    np.savetxt(path, rows, fmt=fmt, delimiter=",", header=header or "", comments="")
    return path


def _args(src: Path, out: Path, **kw: object) -> argparse.Namespace:
    base = dict(format="csv", raw=str(src), output=str(out), raw_samples=False,
                min_static_s=None, threshold=None, window_s=None, trim_s=None,
                columns="ax=2,ay=3,az=4,temp=5", accel_unit="mg", rate_hz=RATE_HZ)
    base.update(kw)
    return argparse.Namespace(**base)


def _refusal(capsys: pytest.CaptureFixture[str], args: argparse.Namespace) -> str:
    """The one line a person reads when the import refuses (and no file is written)."""
    assert run_import(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert not Path(str(args.output)).exists()
    return err


def _table(tmp_path: Path, acc: np.ndarray, temp: np.ndarray) -> Path:
    return _write(tmp_path / "log.csv", np.column_stack([np.full(len(temp), 42652.0), acc,
                                                         temp]))


def test_counts_with_a_wrong_sensitivity_name_the_sensitivity_not_another_unit(
        tmp_path, capsys):
    acc, temp = _warmup()
    src = _table(tmp_path, acc / 1000.0 * 256.0, temp)  # counts at 256 LSB/g
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", accel_unit="counts",
                                 counts_per_g=2560.0))
    assert "median |a| is 0.1008 g, not about 1 g" in err
    assert "the counts read about 258" in err and "not the 2560 given" in err
    assert "--counts-per-g" in err and "looks like" not in err


def test_imu_tk_counts_with_a_wrong_sensitivity_are_refused_at_import(tmp_path, capsys):
    # an imu_tk ASCII log: t and 16-bit counts about mid-scale, 4096 counts per g
    rng = np.random.default_rng(2)
    t = np.arange(3000) / 100.0
    counts = 32768.0 + np.array([0.0, 0.0, 4096.0]) + rng.normal(0, 3, (3000, 3))
    src = tmp_path / "acc.mat"
    np.savetxt(src, np.column_stack([t, counts]), fmt="%.6e")
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", format="imu_tk",
                                 counts_per_g=65536.0, offset=32768.0))
    assert "median |a| is 0.0625 g, not about 1 g" in err
    assert "×16 it is 1 g" in err and "(--counts-per-g 4096)" in err


def test_a_recording_read_with_another_ranges_sensitivity_is_refused_by_calibrate(
        tmp_path, capsys):
    # a firmware that sets ±8 g and divides by the ±2 g sensitivity: a quarter of the
    # acceleration, a warm-up nonetheless (calibrate would hold the scale and fit it)
    rec = _still_warmup(0.252)
    src, model = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, rec)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model))) == 2
    err = capsys.readouterr().err.strip()
    assert "median |a| is 0.2542 g, not about 1 g; ×4 it is 1.017 g" in err
    assert "the recording's ax, ay, az are in g" in err and len(err.splitlines()) == 1
    assert not model.exists()


def test_one_column_for_an_axis_and_the_temperature_is_refused(tmp_path, capsys):
    acc, temp = _warmup()
    src = _table(tmp_path, acc, temp)
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", columns="ax=2,ay=3,az=4,temp=2"))
    assert "--columns: ax and temp both name column '2'" in err


def test_an_acceleration_column_read_as_the_temperature_is_refused(tmp_path, capsys):
    # a second sensor's x axis (mg, 7 mg of noise, about 20 mg) named as the temperature:
    # inside a die's range, it scatters by 7 "°C" from one sample to the next
    acc, temp = _warmup()
    other = 20.0 + np.random.default_rng(3).normal(0, 7, len(temp))
    src = _write(tmp_path / "log.csv", np.column_stack([acc, temp, other]),
                 header="ax,ay,az,die_c,ax2")
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", columns="temp=ax2"))
    assert "temperature scatters by 7" in err and "the column is not a temperature" in err
    assert "check --columns temp=" in err


@pytest.mark.parametrize("convert,looks,fix", [
    (lambda c: np.round(c * 100.0), "hundredths of a °C (-18.72 .. -13.29 °C: --temp-unit "
     "counts --temp-c-per-count 0.01 --temp-offset-c 0)", "or thousandths of a °C"),
    (lambda c: c * 9.0 / 5.0 + 32.0 + 180.0, "°F (81.28 .. 86.71 °C: --temp-unit F)",
     "or hundredths of a °C (1.783 .. 1.881 °C"),
], ids=["centi-degrees", "fahrenheit"])
def test_a_temperature_in_another_unit_names_the_conversion(tmp_path, capsys, convert, looks,
                                                          fix):
    acc, temp = _warmup()
    src = _table(tmp_path, acc, convert(temp))
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv"))
    assert "outside a die's -60 .. 150 °C; it looks like " in err
    assert looks in err and fix in err


def test_a_block_written_twice_is_refused(tmp_path, capsys):
    acc, temp = _warmup()
    rows = np.column_stack([acc, temp])
    rows = np.concatenate([rows[:4000], rows[3000:4000], rows[4000:]])
    src = _write(tmp_path / "log.csv", rows, header="ax,ay,az,temp_c")
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", columns=None))
    assert "data rows 4001..5000 repeat rows 3001..4000 value for value (1000 rows)" in err
    assert "remove the repeated rows" in err


def test_a_time_column_named_in_ms_read_as_seconds_is_refused(tmp_path, capsys):
    acc, temp = _warmup()
    t_ms = np.arange(len(temp)) * 2.0
    src = _write(tmp_path / "log.csv", np.column_stack([t_ms, acc, temp]),
                 header="time_ms,ax,ay,az,temp_c")
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", columns="t=time_ms",
                                 rate_hz=None))
    assert "column 'time_ms': the time column is named in ms but read in s" in err
    assert "give --time-unit ms" in err


def test_a_decimal_comma_is_named_not_blamed_on_a_garbled_line(tmp_path, capsys):
    acc, temp = _warmup(n=200)
    lines = ["ax;ay;az;temp"] + [";".join(f"{v:.3f}".replace(".", ",") for v in row)
                                 for row in np.column_stack([acc, temp])]
    src = tmp_path / "log.csv"
    src.write_text("\n".join(lines) + "\n")
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", columns="temp=temp"))
    assert "a decimal comma" in err and "'.' as the decimal mark" in err
    assert "garbled" not in err and "--bad-lines" not in err


def test_a_temperature_that_is_not_the_sensors_gets_no_steep_model(tmp_path, capsys):
    # 40 5-s means of a board settling by a few mg, with a "temperature" that is another
    # channel's noise (a gyroscope's, 0.6 ± 0.12): held-out error chose a line whose slope
    # is 14 mg/°C, within 2 standard errors of the 5 mg/°C no part exceeds. Applied, it
    # would move readings by 14 mg per "°C" of a channel that is not this die's.
    rng = np.random.default_rng(10)
    n = 40
    channel = 0.6 + rng.normal(0, 0.12, n)
    wander = np.cumsum(rng.normal(0, 1.5e-3, n))
    rec = {"t_s": np.arange(n) * 5.0, "sensor_c": channel,
           "ax": np.full(n, 0.01) + rng.normal(0, 2e-4, n), "ay": 0.02 + wander * 0.5,
           "az": 1.0 + wander, "sd_x": np.full(n, 2e-3), "sd_y": np.full(n, 2e-3),
           "sd_z": np.full(n, 3e-3), "n": np.full(n, 250.0)}
    src, model = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, rec)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model))) == 2
    err = capsys.readouterr().err.strip()
    assert "the fitted bias bz changes by -5.78 mg over the captures' 0.38 .. 0.79 °C" in err
    assert "(-14.1 mg/°C on average), beyond any MEMS accelerometer's offset drift" in err
    assert "--columns temp=NAME --temp-unit" in err and len(err.splitlines()) == 1
    assert not model.exists()


def test_compensate_refuses_readings_that_are_not_in_g(tmp_path, capsys):
    # a model calibrated on a warm-up in g, applied to the same board's log written by a
    # firmware that divides by the ±2 g sensitivity at ±8 g (a quarter of the acceleration)
    rec = _still_warmup(1.002)
    src, model = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, rec)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model))) == 0
    capsys.readouterr()
    quarter = {k: (v / 4.0 if k in ("ax", "ay", "az") else v) for k, v in rec.items()}
    other, out = tmp_path / "quarter.csv", tmp_path / "out.csv"
    write_recording(other, quarter)
    assert cli.run_compensate(SimpleNamespace(model=str(model), recording=str(other),
                                              output=str(out))) == 2
    err = capsys.readouterr().err.strip()
    assert "median |a| is 0.251 g, not about 1 g; ×4 it is 1.004 g" in err
    assert "nothing written" in err and len(err.splitlines()) == 1 and not out.exists()


def test_a_steep_tempco_refusal_names_a_temperature_in_another_unit(tmp_path, capsys):
    # °C declared as °F shrinks the span 1.8× and steepens every slope as much: the
    # refusal of a slope beyond any part's names the unit among its causes
    rng = np.random.default_rng(5)
    t = np.arange(120, dtype=float)
    temp = (20.0 + 0.5 * t / t[-1] - 32.0) * 5.0 / 9.0 + rng.normal(0, 0.005, t.size)
    bz = 0.012 * (t / t[-1])  # 12 mg over 0.28 "°C": 43 mg/°C
    rec = {"t_s": t, "sensor_c": temp, "ax": np.full(t.size, 0.01),
           "ay": np.full(t.size, 0.02) + rng.normal(0, 1e-5, t.size),
           "az": 0.9995 + bz + rng.normal(0, 1e-5, t.size),
           "sd_x": np.full(t.size, 1e-4), "sd_y": np.full(t.size, 1e-4),
           "sd_z": np.full(t.size, 1e-4), "n": np.full(t.size, 50.0)}
    src, model = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, rec)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model))) == 2
    err = capsys.readouterr().err.strip()
    assert "beyond any MEMS accelerometer's offset drift (5 mg/°C)" in err
    assert "is not this sensor's die or is in another unit" in err
    assert "--temp-unit C|F|K" in err and len(err.splitlines()) == 1


def test_a_warmup_read_ten_times_too_short_says_how_long_it_was_read(tmp_path, capsys):
    # a 120-s warm-up at 50 Hz, its times read at 500 Hz (--rate-hz ×10): 12 s of 15 °C/min.
    # "Record a longer warm-up" alone blames the recording; the line names the reading too.
    rec, _ = warmup_log(seconds=120, rate_hz=50, t_start_c=20.0, t_end_c=23.0, tau_s=200)
    cols = {k: (v / 10.0 if k == "t_s" else v) for k, v in rec.columns.items()}
    src, model = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, cols)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model))) == 2
    err = capsys.readouterr().err.strip()
    assert "too few to judge a bias change by held-out error" in err
    assert "its capture means span 8.5 s and 2.05 °C (14.4 °C/min)" in err
    assert "if the log ran longer, its time unit or --rate-hz was read wrong" in err
    assert len(err.splitlines()) == 1 and not model.exists()


def test_a_table_given_as_a_dataflash_log_is_named_once(tmp_path, capsys):
    # main: pymavlink's DFReader printed a "bad header" line per byte (3.6 M lines for the
    # inclinometer's CSV), then the import blamed the IMU instance
    acc, temp = _warmup(n=100)
    src = _table(tmp_path, acc, temp)
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", format="dataflash"))
    assert "not an ArduPilot DataFlash .bin log: it begins '42652.0000,17.41', " in err
    assert "not with a DataFlash message header (bytes A3 95): text" in err
    assert "--format csv" in err and "instance" not in err


def test_m_s2_declared_as_mg_names_the_unit(tmp_path, capsys):
    acc, temp = _warmup()
    src = _table(tmp_path, acc * 9.80665e-3, temp)  # m/s²
    err = _refusal(capsys, _args(src, tmp_path / "rec.csv", accel_unit="mg"))
    assert "median |a| is 0.009885 g, not about 1 g; it looks like m/s² (read as mg)" in err


def _still_warmup(az_g: float) -> dict[str, np.ndarray]:
    """A 5-min warm-up of 60 capture means, z up at ``az_g`` with a 0.7 mg/°C bias change."""
    n = 60
    t = np.arange(n) * 5.0
    temp = 20.0 + 6.0 * t / t[-1]
    return {"t_s": t, "sensor_c": temp, "ax": np.full(n, 0.004), "ay": np.full(n, 0.005),
            "az": az_g + 0.0007 * (temp - 20.0), "n": np.full(n, 2500.0),
            "sd_x": np.full(n, 0.002), "sd_y": np.full(n, 0.002), "sd_z": np.full(n, 0.004)}
