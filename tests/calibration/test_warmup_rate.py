"""A warm-up that heats then cools: the rate term k(T)·dT/dt, and what the model file says.

The logs are 1-s mean rows (mean, sd, n) of a sensor at rest, z up, its die warming
from 25 °C toward 45 °C (τ 10 min) for 15 min and then cooling toward 30 °C.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calibration import cli, export_cli, warmup
from calibration.model_file import load_model, load_model_file
from calibration.recording import write_recording
from calibration.thermal_plant import lag_series

TEMPCO_G_PER_C = np.array([12e-6, -6e-6, 20e-6])  # a linear-plus-quadratic bias drift
CURVE_G_PER_C2 = np.array([0.4e-6, 0.3e-6, -0.5e-6])
NOISE_G = 4e-6  # one 1-s mean's


def _die(t_s: np.ndarray, heat_s: float | None = 900.0) -> np.ndarray:
    hot = 25.0 + 20.0 * (1.0 - np.exp(-t_s / 600.0))
    if heat_s is None:
        return hot
    at_off = 25.0 + 20.0 * (1.0 - np.exp(-heat_s / 600.0))
    return np.where(t_s <= heat_s, hot, 30.0 + (at_off - 30.0) * np.exp(-(t_s - heat_s) / 600.0))


def _log(*, lag_s: float = 0.0, rate_ug_per_c_per_min: float = 0.0, seconds: int = 1500,
         both_ways: bool = True, seed: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(seconds, dtype=float)
    die = _die(t, 900.0 if both_ways else None)
    d = die - 35.0
    acc = np.array([0.0, 0.0, 1.0]) + d[:, None] * TEMPCO_G_PER_C + d[:, None] ** 2 * CURVE_G_PER_C2
    rate_c_per_min = 60.0 * np.gradient(die, t)
    acc = acc + rate_c_per_min[:, None] * np.array([1.0, -0.6, 0.8]) * rate_ug_per_c_per_min * 1e-6
    acc = acc + rng.normal(0.0, NOISE_G, acc.shape)
    channel = lag_series(die, 1.0, lag_s) if lag_s else die
    sd = np.full(seconds, NOISE_G * 7.0)
    return {"t_s": t, "sensor_c": channel + rng.normal(0.0, 0.005, seconds),
            "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2],
            "sd_x": sd, "sd_y": sd, "sd_z": sd, "n": np.full(seconds, 50.0)}


def _calibrate(tmp_path: Path, cols: dict[str, np.ndarray], capsys) -> tuple[dict, Path]:
    src, model = tmp_path / "warmup.csv", tmp_path / "model.json"
    write_recording(src, cols)
    args = SimpleNamespace(recording=str(src), output=str(model), json=True)
    assert cli.run_calibrate(args) == 0
    return json.loads(capsys.readouterr().out), model


def _compensate_residual_ug(tmp_path: Path, cols: dict[str, np.ndarray], model: Path,
                            die_drift_g: np.ndarray) -> np.ndarray:
    """Per axis: RMS (µg) of the compensated output less its mean, over 5-s means."""
    src, out = tmp_path / "all.csv", tmp_path / "comp.csv"
    write_recording(src, cols)
    args = SimpleNamespace(model=str(model), recording=str(src), output=str(out),
                           extrapolate=True)
    assert cli.run_compensate(args) == 0
    with out.open() as f:
        rows = list(csv.DictReader(f))
    comp = np.array([[float(r[c]) for c in ("cx", "cy", "cz")] for r in rows])
    means = comp[: comp.shape[0] // 5 * 5].reshape(-1, 5, 3).mean(axis=1)
    return np.sqrt(np.mean((means - means.mean(axis=0)) ** 2, axis=0)) * 1e6



def _residual_with_and_without_rate_ug(tmp_path, cols, model_path):
    """compensate's residual (µg per axis) with the model as written and with its rate term
    removed from the model file."""
    with_rate = _compensate_residual_ug(tmp_path, cols, model_path, TEMPCO_G_PER_C)
    doc_file = json.loads(model_path.read_text())
    doc_file["temperature"]["rate"] = None
    no_rate = tmp_path / "no_rate.json"
    no_rate.write_text(json.dumps(doc_file))
    return with_rate, _compensate_residual_ug(tmp_path, cols, no_rate, TEMPCO_G_PER_C)

def test_a_lagging_channel_on_a_warmup_and_cooldown_gets_a_rate_term(tmp_path, capsys):
    # (also: 1500 densely spaced temperatures over 15 °C are many temperatures, not one)
    cols = _log(lag_s=60.0)
    doc, model_path = _calibrate(tmp_path, cols, capsys)
    assert doc["rate_term"] is not None
    assert any("rate term k·dT/dt fitted" in n for n in doc["notes"])
    model = load_model(model_path)
    assert model.temperature_rate is not None
    assert len(model.temperature_rate["gain_ug_per_c_per_min"]) == 3
    # What the rate term buys, through `compensate` itself: the same model without it
    # leaves the lag's error (tempco × 60 s × dT/dt: tens of µg); with it, about the
    # noise of a 5-s mean (4 µg / √5 ≈ 1.8 µg).
    with_rate, without = _residual_with_and_without_rate_ug(tmp_path, cols, model_path)
    assert np.all(with_rate < 4.0), with_rate
    assert without[2] > 3.0 * with_rate[2], (without, with_rate)


def test_a_rate_sensitive_part_gets_its_gain_back(tmp_path, capsys):
    doc, model_path = _calibrate(tmp_path, _log(rate_ug_per_c_per_min=40.0), capsys)
    gain = np.asarray(load_model(model_path).temperature_rate["gain_ug_per_c_per_min"])
    # the constant part of the gain (at mid-range) is the part's, within a few µg/(°C/min)
    np.testing.assert_allclose(gain[:, 0], [40.0, -24.0, 32.0], atol=4.0)



def test_a_rate_term_is_kept_only_on_the_axes_whose_bias_follows_dt_dt(tmp_path, capsys):
    # y and z follow dT/dt (-24 and +32 µg per °C/min), x does not: the three axes
    # together choose a rate term, but x's own held-out error gains nothing beyond that
    # gain's standard error, so x gets none (a gain fitted to x's noise would move x by
    # k·dT/dt where nothing moves it).
    cols = _log()
    rate_c_per_min = 60.0 * np.gradient(_die(cols["t_s"]), cols["t_s"])
    cols["ay"] = cols["ay"] - 24e-6 * rate_c_per_min
    cols["az"] = cols["az"] + 32e-6 * rate_c_per_min
    doc, model_path = _calibrate(tmp_path, cols, capsys)
    choice = doc["axis_choice"]
    assert [choice[a]["rate_term"] for a in ("bx", "by", "bz")] == [False, True, True]
    assert choice["bx"]["degree"] >= 1  # x's bias still changes with temperature
    gain = np.asarray(load_model(model_path).temperature_rate["gain_ug_per_c_per_min"])
    assert np.all(gain[0] == 0.0)
    np.testing.assert_allclose(gain[1:, 0], [-24.0, 32.0], atol=4.0)
    assert any(n.startswith("bx: degree") and "the rate term does not lower" in n
               for n in doc["notes"]), doc["notes"]
    assert any("rate term k·dT/dt fitted on by, bz" in n for n in doc["notes"])


def test_a_rate_sensitive_part_gets_its_gain_back_from_fit_rows_with_gaps(tmp_path, capsys):
    # The held-out split's fit rows: alternate 10-s blocks of the log. A quiet channel
    # (0.3 mK) makes the 5-s window dT/dt's, where the rows beside each gap have 3 rows in
    # their window: read as a difference across the gap, dT/dt there was a fraction of the
    # true rate and the fitted gain a polynomial in T far from the part's constant.
    cols = _log(rate_ug_per_c_per_min=40.0)
    cols["sensor_c"] = _die(cols["t_s"]) + np.random.default_rng(5).normal(0.0, 3e-4,
                                                                             cols["t_s"].size)
    fit_rows = (cols["t_s"] // 10) % 2 == 0
    doc, model_path = _calibrate(tmp_path, {k: v[fit_rows] for k, v in cols.items()}, capsys)
    assert doc["rate_term"]["window_s"] == 5.0
    model = load_model(model_path)
    gain = np.asarray(model.temperature_rate["gain_ug_per_c_per_min"])
    # the gain k(T) over the log's temperatures is the part's constant, on every axis
    x = model.x_of(cols["sensor_c"][fit_rows])
    k_over_span = np.array([np.polyval(g[::-1], x) for g in gain])
    truth = np.array([40.0, -24.0, 32.0])[:, None]
    assert np.max(np.abs(k_over_span - truth)) < 4.0, (k_over_span.min(1), k_over_span.max(1))

def test_a_one_way_warmup_has_no_rate_term(tmp_path, capsys):
    # Warming only, the channel reading the die: dT/dt = (45 °C − T)/10 min is a function
    # of T and the polynomial already absorbs it, so no rate term is even tried. (With a
    # lagging channel the log's first minutes are a rest then a heating for the channel,
    # its rate rising from 0 while T hardly moves: that onset identifies the lag, see
    # test_a_rest_then_a_heating_with_a_lagging_channel_gets_a_rate_term.)
    doc, model_path = _calibrate(tmp_path, _log(both_ways=False), capsys)
    assert doc["rate_identifiability"]["tried"] is False
    assert doc["rate_term"] is None and doc["rate_selection"] == []
    assert load_model(model_path).temperature_rate is None


def test_the_model_file_says_how_a_warmup_is_compensated(tmp_path, capsys):
    _, model_path = _calibrate(tmp_path, _log(), capsys)
    temp = json.loads(model_path.read_text())["temperature"]
    assert temp["compensation"]["otherwise"]["kind"] == "capture_mean"
    assert temp["compensation"]["per_step"]["enabled"] is False
    # a streaming consumer's filter: about one capture, not the soak models' 600 s
    assert temp["streaming_filter"]["tau_s"] == 5.0
    _, conditioning = load_model_file(model_path)
    assert conditioning.capture_block_s == 5.0 and conditioning.tau_s == 5.0


@pytest.mark.parametrize("fmt", ["c", "px4"])
def test_export_of_a_rate_term_refuses_or_lists_it(tmp_path, capsys, fmt):
    _, model_path = _calibrate(tmp_path, _log(lag_s=60.0), capsys)
    out = tmp_path / f"out.{fmt}"
    code = export_cli.run_export(SimpleNamespace(model=str(model_path), output=str(out),
                                                 format=fmt, instance=None, device_id=None))
    err = capsys.readouterr().err
    if fmt == "c":
        assert code == 2 and not out.exists()
        assert "temperature.rate" in err and "rate term" in err
    else:
        assert code == 0
        assert "rate term k(T)*dT/dt" in err and "rate term k(T)*dT/dt" in out.read_text()


def test_a_board_tilting_as_it_warms_is_refused_not_a_30_mg_per_c_tempco(tmp_path, capsys):
    # 2 minutes, the channel creeping up 0.5 °C while the board tilts 15 mrad about x (y
    # and z readings move by ~15 mg): no offset drifts 30 mg/°C, so no model is written.
    rng = np.random.default_rng(5)
    t = np.arange(120, dtype=float)
    tilt = 0.015 * t / t[-1]
    cols = {"t_s": t, "sensor_c": 47.2 + 0.5 * t / t[-1] + rng.normal(0, 0.01, t.size),
            "ax": np.full(t.size, 0.99), "ay": 0.1 - 0.1 * tilt + rng.normal(0, 1e-5, t.size),
            "az": -0.1 + 0.1 * tilt + tilt * 0.99 + rng.normal(0, 1e-5, t.size),
            "sd_x": np.full(t.size, 1e-4), "sd_y": np.full(t.size, 1e-4),
            "sd_z": np.full(t.size, 1e-4), "n": np.full(t.size, 50.0)}
    src, model = tmp_path / "hot.csv", tmp_path / "model.json"
    write_recording(src, cols)
    code = cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model)))
    err = capsys.readouterr().err.strip()
    assert code == 2 and not model.exists()
    assert "mg/°C" in err and "beyond any MEMS accelerometer's offset drift" in err
    assert "keep the board still" in err and len(err.splitlines()) == 1


def test_a_short_log_with_a_jumping_channel_gets_no_rate_term():
    # Six 1-s samples at one orientation, the channel jumping 0.2-0.3 °C up and down (a
    # PX4 log's sensor_accel at 1 Hz): its "heating and cooling" is the channel's jitter,
    # shorter than the window dT/dt is read over. No rate term may be fitted to it (one
    # was "preferred" held out and written into a model that made x worse).
    from calibration.fitting import fit
    from calibration.gate import GateRefusal
    from calibration.recording import Recording

    rng = np.random.default_rng(3)
    n = 6
    acc = np.array([0.07, 0.025, -0.99]) + rng.normal(0.0, 4e-3, (n, 3))
    rec = Recording.from_columns({
        "t_s": np.arange(n, dtype=float), "sensor_c": np.array([40.0, 40.3, 40.1, 40.3, 40.1,
                                                                40.3]),
        "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2], "n": np.ones(n)})
    try:
        result = fit(rec)
    except GateRefusal:
        return  # no model at all: nothing with a rate term either
    assert result.report.get("rate_term") is None
    assert not result.report.get("rate_selection")
    assert not any("rate term k·dT/dt" in note for note in result.report["notes"])
    # and the report says why none was tried
    assert result.report["rate_identifiability"]["tried"] is False
    assert any(note.startswith("no rate term tried") for note in result.report["notes"])


def _rest_then_heat(*, lag_s: float, rest_s: int = 300, heat_s: int = 300,
                    seed: int = 2) -> dict[str, np.ndarray]:
    """1-s rows of a board that rests at 20 °C, then heats toward 30 °C (τ 120 s): the
    inclinometer log's shape. The channel lags the die by ``lag_s`` (first order)."""
    rng = np.random.default_rng(seed)
    t = np.arange(rest_s + heat_s, dtype=float)
    die = 20.0 + 10.0 * (1.0 - np.exp(-np.clip(t - rest_s, 0.0, None) / 120.0))
    d = die - 25.0
    acc = np.array([0.0, 0.0, 1.0]) + d[:, None] * TEMPCO_G_PER_C + d[:, None] ** 2 * CURVE_G_PER_C2
    acc = acc + rng.normal(0.0, NOISE_G, acc.shape)
    channel = lag_series(die, 1.0, lag_s) if lag_s else die
    sd = np.full(t.size, NOISE_G * 7.0)
    return {"t_s": t, "sensor_c": channel + rng.normal(0.0, 0.005, t.size),
            "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2],
            "sd_x": sd, "sd_y": sd, "sd_z": sd, "n": np.full(t.size, 50.0)}


def test_a_rest_then_a_heating_with_a_lagging_channel_gets_a_rate_term(tmp_path, capsys):
    # Heating only, but after a rest: zero and fast rates at the same temperature, so
    # dT/dt is not a function of T and a rate term is identified (it used to be tried
    # only on logs that heat and cool).
    cols = _rest_then_heat(lag_s=30.0)
    doc, model_path = _calibrate(tmp_path, cols, capsys)
    check = doc["rate_identifiability"]
    assert check["tried"] is True
    assert check["share_not_a_function_of_t"] >= warmup.RATE_MIN_SHARE
    assert check["window_s"] < 120.0  # short against the 300-s heating
    assert doc["rate_term"] is not None
    assert any("rate term k·dT/dt fitted" in n for n in doc["notes"])
    # through `compensate`: the lag leaves tens of µg at the onset of heating (z tempco
    # 20 µg/°C × 30 s × 5 °C/min); the rate term takes it to near a 5-s mean's noise
    with_rate, without = _residual_with_and_without_rate_ug(tmp_path, cols, model_path)
    assert with_rate[2] < 0.5 * without[2], (with_rate, without)
    assert np.all(with_rate < 4.0), with_rate


def test_a_steady_ramp_with_a_lagging_channel_gets_no_rate_term(tmp_path, capsys):
    # Heating at a constant 1 °C/min, the channel 60 s behind: dT/dt is the same at every
    # temperature (a function of T), the lag is a constant offset of T that the
    # polynomial absorbs, and no rate term may be fitted.
    rng = np.random.default_rng(4)
    t = np.arange(1200, dtype=float)
    die = 20.0 + t / 60.0
    d = die - 30.0
    acc = np.array([0.0, 0.0, 1.0]) + d[:, None] * TEMPCO_G_PER_C + d[:, None] ** 2 * CURVE_G_PER_C2
    acc = acc + rng.normal(0.0, NOISE_G, acc.shape)
    sd = np.full(t.size, NOISE_G * 7.0)
    cols = {"t_s": t, "sensor_c": die - 1.0 + rng.normal(0.0, 0.005, t.size),
            "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2],
            "sd_x": sd, "sd_y": sd, "sd_z": sd, "n": np.full(t.size, 50.0)}
    doc, model_path = _calibrate(tmp_path, cols, capsys)
    assert doc["rate_identifiability"]["tried"] is False
    assert doc["rate_term"] is None and doc["rate_selection"] == []
    assert any(n.startswith("no rate term tried: ") for n in doc["notes"])
    assert load_model(model_path).temperature_rate is None
