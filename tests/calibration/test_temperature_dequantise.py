"""A 1 °C temperature channel: the die temperature rebuilt from its steps' transitions in time."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import bench_temperature_dequantise as bench
from calibration.captures import warmup_captures
from calibration.recording import Recording
from calibration.temperature_dequantise import coarse_lsb_c, dequantise
from tests.calibration import dequantise_cases as cases

STEP_RMS_C = 1.0 / np.sqrt(12.0)  # what a step value is wrong by, RMS (0.29 °C)


# The die traces are the benchmark's (benchmarks/bench_temperature_dequantise.py).
_exponential, _overshoot = cases.exponential, cases.overshoot
_rest_heat_rest, _heat_cool = cases.rest_heat_rest, cases.heat_cool
_captures, _warmup_rows = cases.captures, cases.warmup_rows
RATE_HZ = cases.RATE_HZ


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - np.mean(x)) ** 2)))  # a constant offset is harmless


@pytest.mark.parametrize("profile, bound_c", [
    (_exponential, 0.10), (_heat_cool, 0.06), (_overshoot, 0.15), (_rest_heat_rest, 0.16)])
@pytest.mark.parametrize("noise_c", [0.0, 0.02, 0.1])
@pytest.mark.parametrize("block_s", [1.0, 5.0])
def test_rebuilt_die_temperature_beats_the_step_values(profile, bound_c, noise_c,
                                                       block_s) -> None:
    # Achieved, RMS against the truth (the step values: 0.17-0.29 °C; the table of
    # benchmarks/bench_temperature_dequantise.py): exponential 0.07, heat-cool 0.05,
    # overshoot (a peak and a trough inside a step) 0.14, a rest inside a step for a
    # quarter of the log 0.15 (the rest's own 0.3 °C offset is not in the data).
    t, read, truth = _captures(profile, noise_c, block_s)
    dq = dequantise(t, read)
    assert dq.lsb_c == pytest.approx(1.0, abs=1e-9)
    # up to 0.1 °C of noise (a flicker ±0.2 °C around each threshold): the crossings
    assert dq.regime == "crossings" and dq.transitions >= 8
    assert _rms(dq.temperature_c - truth) < bound_c < STEP_RMS_C
    assert _rms(dq.temperature_c - truth) < 0.85 * _rms(read - truth)
    # never outside the band of the levels read, never beyond a level's neighbour
    assert dq.temperature_c.min() >= read.min() - 0.5 and dq.temperature_c.max() <= \
        read.max() + 0.5
    assert np.max(np.abs(dq.temperature_c - truth)) < 0.5


@pytest.mark.parametrize("profile", [_exponential, _heat_cool, _overshoot, _rest_heat_rest])
@pytest.mark.parametrize("noise_c", [0.2, 0.35, 0.6])
def test_a_dithered_channel_is_read_from_its_share_of_upper_readings(profile, noise_c) -> None:
    # noise of 0.2-0.6 LSB before rounding: the readings flicker between levels for most
    # of the log; the capture means' fraction at the upper level is where the die sits
    t, read, truth = _captures(profile, noise_c, 1.0)
    assert np.mean(np.abs(read - np.round(read)) > 0.02) > 0.5  # mostly off the levels
    dq = dequantise(t, read, np.full(t.size, RATE_HZ))
    assert dq.regime == "dither" and dq.lsb_c == pytest.approx(1.0)
    assert dq.dither_lsb == pytest.approx(noise_c, abs=0.1 + 0.25 * noise_c)
    assert "dithered" in (dq.note() or "") and "share of readings one level up" in dq.note()
    rebuilt, as_read = _rms(dq.temperature_c - truth), _rms(read - truth)
    # the crossing instants alone (the regime this replaces) on the same readings
    crossings = _rms(dequantise_crossings(t, read).temperature_c - truth)
    assert rebuilt < 0.05 and rebuilt < 0.6 * as_read and rebuilt < crossings


def dequantise_crossings(t: np.ndarray, read: np.ndarray):
    """The crossing-instant rebuild alone (the dithered regime switched off; uncached: the
    memo of ``dequantise`` holds the rebuild with the dithered regime on)."""
    import calibration.temperature_dequantise as tdq

    saved = tdq.rebuild_dithered
    tdq.rebuild_dithered = lambda *a: None
    try:
        return tdq.dequantise_uncached(t, read, np.full(t.size, RATE_HZ))
    finally:
        tdq.rebuild_dithered = saved


def test_a_turning_point_stays_inside_its_step() -> None:
    # 29 -> 30 -> 29: the peak (30.45 °C) is inside level 30; the rebuilt trace peaks
    # inside that level's band and not beyond it, and rises and falls once around it
    t, read, truth = _captures(_overshoot, 0.0, 5.0)
    dq = dequantise(t, read)
    assert dq.turning_points >= 2
    peak = (t > 250.0) & (t < 550.0)
    assert 29.5 < dq.temperature_c[peak].max() <= 30.5
    i = int(np.argmax(dq.temperature_c[peak]))
    rise, fall = np.diff(dq.temperature_c[peak][: i + 1]), np.diff(dq.temperature_c[peak][i:])
    assert np.all(rise >= -1e-9) and np.all(fall <= 1e-9)


def test_flicker_at_a_threshold_holds_the_threshold() -> None:
    # single readings (no averaging) toggling 25/26 for minutes around a crossing at
    # t = 300 s (0.1 °C/min, 0.05 °C of noise): the rebuilt trace is at the threshold
    # (25.5) through the flicker, below it before, above it after
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 600.0, 2.0)
    truth = 25.0 + t / 600.0
    read = np.round(truth + rng.normal(0.0, 0.05, t.size))
    toggles = t[1:][np.diff(read) != 0]
    assert toggles.size > 3  # it does flicker
    dq = dequantise(t, read)
    assert dq.rebuilt
    during = (t > toggles[0] + 10.0) & (t < toggles[-1] - 10.0)
    assert np.all(np.abs(dq.temperature_c[during] - 25.5) < 0.05)
    assert np.all(dq.temperature_c[t < toggles[0] - 10.0] < 25.5)
    assert np.all(dq.temperature_c[t > toggles[-1] + 10.0] > 25.5)
    assert np.max(np.abs(dq.temperature_c - truth)[during]) < 0.15
    # one crossing only: the ends hold their steps' values (the step values: 0.29 °C)
    assert _rms(dq.temperature_c - truth) < 0.15 < _rms(read - truth)


def test_a_finely_quantised_channel_is_returned_unchanged() -> None:
    for lsb in (0.0078125, 0.06, 0.11):
        t, read, _ = _captures(_exponential, 0.01, 5.0, lsb_c=lsb)
        assert coarse_lsb_c(read) == 0.0
        dq = dequantise(t, read)
        assert not dq.rebuilt and dq.note() is None
        np.testing.assert_array_equal(dq.temperature_c, read)
    # raw single readings of a 0.06 °C channel, and a continuous (unquantised) one
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 600.0, 0.5)
    raw = np.round((25.0 + t / 100.0 + rng.normal(0, 0.02, t.size)) / 0.06) * 0.06
    np.testing.assert_array_equal(dequantise(t, raw).temperature_c, raw)
    smooth = 25.0 + t / 100.0
    np.testing.assert_array_equal(dequantise(t, smooth).temperature_c, smooth)


def test_an_evenly_sampled_straight_ramp_of_capture_means_is_not_a_lattice() -> None:
    # 50-sample capture means 0.169 °C apart: their sums are spaced 8.47 °C alike, which
    # read as a dithered channel's lattice claimed an 8.47-°C LSB; a dithered channel's
    # sums scatter by several LSB from capture to capture instead of one step each
    t = np.arange(60, dtype=float) * 5.0
    ramp = 20.0 + 10.0 * t / t[-1]
    n = np.full(t.size, 50.0)
    dq = dequantise(t, ramp, n)
    assert not dq.rebuilt and dq.note() is None
    np.testing.assert_array_equal(dq.temperature_c, ramp)


def test_half_and_twice_the_lsb_are_not_taken_for_it() -> None:
    # a capture mean midway between levels now and then (a crossing at mid-capture) does not
    # make the LSB 0.5 °C; rests on even levels do not make it 2 °C
    t, read, _ = _captures(_rest_heat_rest, 0.1, 5.0)
    assert coarse_lsb_c(read) == pytest.approx(1.0, abs=1e-9)
    assert coarse_lsb_c(np.r_[read, [22.5, 22.5, 24.5, 24.5]]) == pytest.approx(1.0, abs=1e-9)


def test_a_channel_that_never_changes_level_is_left_as_read() -> None:
    t = np.arange(0.0, 600.0, 5.0)
    read = np.full(t.size, 25.0)
    read[3::7] = 26.0  # a touch now and then, no settled second level
    dq = dequantise(t, read)
    np.testing.assert_array_equal(dq.temperature_c, read)


def test_warmup_captures_rebuild_and_say_so() -> None:
    t, read, truth = _captures(_heat_cool, 0.01, 5.0)
    n = t.size
    means = Recording.from_columns({"t_s": t, "sensor_c": read, "ax": np.zeros(n),
                                    "ay": np.zeros(n), "az": np.ones(n)})
    out, note = warmup_captures(means)
    assert note is not None and "quantised at 1 °C" in note and "transitions" in note
    assert note in out.notes
    assert _rms(out.temperature_c() - truth) < 0.06
    np.testing.assert_array_equal(out.raw_g, means.raw_g)
    # a fine channel: the same recording back, nothing said
    fine = Recording.from_columns({"t_s": t, "sensor_c": truth, "ax": np.zeros(n),
                                   "ay": np.zeros(n), "az": np.ones(n)})
    same, said = warmup_captures(fine)
    assert same is fine and said is None


def test_calibrate_fits_a_warmup_in_the_rebuilt_temperature_and_says_so() -> None:
    from calibration.fitting import fit

    rec, die = _warmup_rows(1.0)
    res = fit(rec)
    assert res.kind == "warmup"
    said = [n for n in res.report["notes"] if "quantised at 1 °C" in n]
    assert said and "transitions in time" in said[0]
    assert any("quantised at 1 °C" in n for n in res.model.notes)
    # the fit's own temperatures are the rebuilt ones, and its residuals are far below
    # what the step values leave (1 mg/°C × 0.29 °C RMS)
    assert _rms(res.row_temperature_c - die) < 0.06
    assert float(np.sqrt(np.mean(res.residuals_ug[:, 2] ** 2))) < 100.0
    # a fine channel: nothing rebuilt, nothing said
    fine, _ = _warmup_rows(0.0078125)
    assert not [n for n in fit(fine).report["notes"] if "quantised at" in n]


def test_compensate_rebuilds_the_same_channel_and_says_so(tmp_path, capsys) -> None:
    import csv
    import json
    from types import SimpleNamespace

    from calibration import cli
    from calibration.recording import write_recording

    rec, _ = _warmup_rows(1.0)
    src, model, out = tmp_path / "w.csv", tmp_path / "model.json", tmp_path / "comp.csv"
    write_recording(src, rec.columns)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model),
                                             json=True)) == 0
    doc = json.loads(capsys.readouterr().out)
    assert any("quantised at 1 °C" in n for n in doc["notes"])
    assert cli.run_compensate(SimpleNamespace(model=str(model), recording=str(src),
                                              output=str(out), extrapolate=True)) == 0
    said = capsys.readouterr().out
    assert "quantised at 1 °C: die temperature rebuilt" in said
    with out.open() as f:
        cz = np.array([float(r["cz"]) for r in csv.DictReader(f)])
    # the bias change (15 mg over the log) compensated to the rebuild's error: at the step
    # values it would be 1 mg/°C × 0.29 °C ≈ 0.29 mg RMS
    assert _rms(cz) < 1e-4


def test_one_crossing_on_a_reading_time_is_finite_and_in_band() -> None:
    # 25 for 10 readings, 26 for 10: one crossing, halfway between two reading times
    t = np.arange(20.0)
    read = np.r_[np.full(10, 25.0), np.full(10, 26.0)]
    dq = dequantise(t, read)
    assert dq.rebuilt and dq.transitions == 1
    assert np.all(np.isfinite(dq.temperature_c))
    assert np.all(np.abs(dq.temperature_c - read) <= 0.5)
    assert np.all(np.diff(dq.temperature_c) >= 0)
    # a crossing on a reading's own time (a capture mean exactly half at each level)
    read_half = np.r_[np.full(10, 25.0), [25.5], np.full(9, 26.0)]
    dq = dequantise(t, read_half)
    assert np.all(np.isfinite(dq.temperature_c)) and dq.temperature_c[10] == pytest.approx(25.5)


def test_a_fine_channel_that_rests_at_two_temperatures_is_not_a_staircase() -> None:
    # A fine channel (1/64 °C, 0.004 °C of noise), 1-s means of 50 samples: a rest at −8.4 °C,
    # a heating with an overshoot, then 25 min settled at 25.8 °C. Most means sit within
    # 2 % of a "34.2 °C LSB" of the two rests, but they are not values a channel prints
    # again and again: the temperature is used as read.
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 2500.0, 1.0)
    heat = np.clip(t - 300.0, 0.0, None)
    truth = -8.4 + 34.2 * (1.0 - np.exp(-heat / 131.0)) + 3.0 * np.sin(heat / 90.0) * np.exp(
        -heat / 200.0)
    samples = truth[:, None] + rng.normal(0.0, 0.004, (t.size, 50))
    means = (np.round(samples * 64.0) / 64.0).mean(axis=1)
    dq = dequantise(t, means, np.full(t.size, 50.0))
    assert not dq.rebuilt and dq.lsb_c == 0.0
    assert np.array_equal(dq.temperature_c, means)


_linear_ramp, _cut_exponential = bench.linear_ramp, bench.cut_exponential


@pytest.mark.parametrize("profile, kinds", [
    (_overshoot, ["rest", "peak", "trough", "rest"]),  # a slow start, 2 turns, its plateau
    (_rest_heat_rest, ["rest", "rest"]),
    (_heat_cool, ["peak", "rest"]),  # the top, and the cooling slowing inside a step
    (_exponential, ["rest"]),  # the plateau it settles towards
    (_linear_ramp, []), (_cut_exponential, [])])
@pytest.mark.parametrize("noise_c", [0.0, 0.02])
def test_spans_the_crossings_cannot_resolve_are_found_and_bounded(profile, kinds,
                                                                  noise_c) -> None:
    t, read, truth = _captures(profile, noise_c, 5.0)
    dq = dequantise(t, read, np.full(t.size, 250.0))
    assert dq.regime == "crossings"
    assert [s.kind for s in dq.unresolved] == kinds
    inside = dq.unresolved_mask(t)
    assert int(np.sum(inside)) == sum(s.readings for s in dq.unresolved)
    for s in dq.unresolved:
        here = (t >= s.t_start_s) & (t <= s.t_end_s)
        assert s.readings == int(np.sum(here)) and s.samples == 250 * s.readings
        assert s.high_c - s.low_c == pytest.approx(1.0) and s.low_c < s.level_c < s.high_c
        # the bound holds the truth (a capture straddling the crossing: within its share)
        assert truth[here].min() >= s.low_c - 0.05 and truth[here].max() <= s.high_c + 0.05
    if kinds:
        # where the rebuild is worst: its error inside the spans is larger than outside
        err = np.abs(dq.temperature_c - truth - np.mean(dq.temperature_c - truth))
        assert np.sqrt(np.mean(err[inside] ** 2)) > 1.5 * np.sqrt(np.mean(err[~inside] ** 2))
        assert "NOT RESOLVED" in (dq.note() or "") and kinds[0] in (dq.note() or "")
    else:
        assert "NOT RESOLVED" not in (dq.note() or "")


def test_the_report_names_the_unresolved_spans_and_what_the_fit_took_there(tmp_path,
                                                                         capsys) -> None:
    import json
    from types import SimpleNamespace

    from calibration import cli
    from calibration.recording import write_recording

    rec, die = _warmup_rows(1.0)
    src, model = tmp_path / "w.csv", tmp_path / "model.json"
    write_recording(src, rec.columns)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model),
                                             json=True)) == 0
    doc = json.loads(capsys.readouterr().out)
    got = doc["unresolved_temperature"]
    assert [s["kind"] for s in got["spans"]] == ["peak", "rest"]
    assert got["readings_inside"] == sum(s["readings"] for s in got["spans"]) > 0
    assert got["readings"] == len(rec) == doc["captures"]  # nothing silently dropped
    assert got["samples_inside"] == 250 * got["readings_inside"]
    assert got["treatment"].startswith("kept in the fit at the rebuilt value")
    peak = got["spans"][0]
    assert (peak["low_c"], peak["level_c"], peak["high_c"]) == (33.5, 34.0, 34.5)
    # the truth inside each span is within its stated bound
    for s in got["spans"]:
        here = (rec.t_s >= s["t_start_s"]) & (rec.t_s <= s["t_end_s"])
        assert s["low_c"] - 0.05 <= die[here].min() and die[here].max() <= s["high_c"] + 0.05
    said = [n for n in doc["notes"] if "NOT RESOLVED below the step's band" in n]
    assert said and f"{got['readings_inside']} of {len(rec)} capture means" in said[0]
    # the text report says the same, with the span's times, step and bound
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model),
                                             json=False)) == 0
    text = capsys.readouterr().out
    assert "peak at 921..1012 s in the 34 °C step (18 readings): between 33.5 and 34.5 °C" \
        in text
    # a log without a rest or a turn inside a step: nothing said
    t, read, truth = _captures(_linear_ramp, 0.01, 5.0, seed=5)
    n = t.size
    cols = dict(rec.columns)
    cols.update({"t_s": t, "sensor_c": read, "az": 1.0 + 1e-3 * (truth - 27.0)})
    from calibration.fitting import fit

    res = fit(Recording.from_columns({k: v[:n] for k, v in cols.items()}))
    assert res.report["unresolved_temperature"] is None
    assert not [x for x in res.report["notes"] if "NOT RESOLVED" in x]
