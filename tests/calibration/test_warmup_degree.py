"""A warm-up's degree, chosen by held-out error on interpolated temperatures.

The logs are 1-s mean rows of a board at rest, z up, that rests at 20 °C and then
heats to 24 °C in a couple of minutes (a log like the one-orientation warm-ups of
issue 20). z's bias bends: most of its change comes in the first third of the heating
(a cubic, steepest at the cold end); x and y do not change with temperature.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from calibration import cli, warmup
from calibration.model_file import load_model
from calibration.recording import write_recording

NOISE_G = 20e-6  # one 1-s mean's
BEND_G = 80e-6
LO_C, HI_C = 20.0, 24.0


def _bend_g(T: np.ndarray, bend_g: float) -> np.ndarray:
    """z's bias change: bend_g · (1 − (1 − u)³), u the position in LO_C … HI_C (70 % of
    the change over the first third of the span)."""
    u = (np.asarray(T, float) - LO_C) / (HI_C - LO_C)
    return bend_g * (1.0 - (1.0 - u) ** 3)


def _log(*, seed: int, rest_s: int = 600, heat_s: int = 120, bend_g: float = BEND_G,
         slope_g_per_c: float = 0.0) -> dict[str, np.ndarray]:
    """Rest at LO_C, then heat to HI_C (exponential approach over ``heat_s``); z bends
    by ``bend_g`` (or, with ``slope_g_per_c``, every axis changes linearly instead)."""
    rng = np.random.default_rng(seed)
    t = np.arange(rest_s + heat_s, dtype=float)
    rise = (1.0 - np.exp(-(t - rest_s) / (heat_s / 3.0))) / (1.0 - np.exp(-3.0))
    die = np.where(t < rest_s, LO_C, LO_C + (HI_C - LO_C) * rise)
    acc = np.tile([0.0, 0.0, 1.0], (t.size, 1))
    if slope_g_per_c:
        acc += (die - LO_C)[:, None] * slope_g_per_c * np.array([1.0, -0.5, 0.8])
    else:
        acc[:, 2] += _bend_g(die, bend_g)
    acc += rng.normal(0.0, NOISE_G, acc.shape)
    sd = np.full(t.size, NOISE_G * 7.0)
    return {"t_s": t, "sensor_c": die + rng.normal(0.0, 0.005, t.size),
            "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2],
            "sd_x": sd, "sd_y": sd, "sd_z": sd, "n": np.full(t.size, 50.0)}


def _calibrate(tmp_path: Path, cols: dict[str, np.ndarray], capsys, *, json_out: bool
               ) -> tuple[str, Path]:
    src, model = tmp_path / "warmup.csv", tmp_path / "model.json"
    write_recording(src, cols)
    args = SimpleNamespace(recording=str(src), output=str(model), json=json_out)
    assert cli.run_calibrate(args) == 0
    return capsys.readouterr().out, model


def test_held_out_captures_lie_between_fitted_temperatures():
    # A warm-up that rests at 20 °C and then heats: every held-out capture (fold 0 or 1)
    # is inside the span of the captures fitted with it (the other fold and the ends):
    # the test interpolates, as a compensation in the valid range does. (Time blocks held
    # out the hottest captures whole: an extrapolation.)
    T = _log(seed=0)["sensor_c"]
    folds = warmup._folds(T)
    assert set(np.unique(folds)) == {0, 1, 2}
    for held in (0, 1):
        fitted = T[folds != held]
        assert np.all(T[folds == held] > fitted.min())
        assert np.all(T[folds == held] < fitted.max())


def test_a_bend_at_the_cold_end_gets_a_curve_that_follows_it(tmp_path, capsys):
    # z bends by 80 µg, four times one capture's noise (the inclinometer: about
    # 4 mg against 1 mg). Held-out error on the few heating captures is itself noisy, so
    # this asks for 4 logs of 5, not every one. (Time-block folds, which held out the hot
    # end whole, chose a line for 2 of these 5.)
    good = []
    for seed in range(5):
        cols = _log(seed=seed, bend_g=BEND_G)
        out, model_path = _calibrate(tmp_path, cols, capsys, json_out=True)
        doc = json.loads(out)
        held = doc["heldout_rms_mg_xyz"]
        model = load_model(model_path)
        T = np.linspace(LO_C + 0.1, HI_C - 0.1, 41)
        change = model.params_vector_at(T)[:, 2] - model.params_vector_at(T[:1])[:, 2]
        truth = _bend_g(T, BEND_G) - _bend_g(T[:1], BEND_G)
        good.append(
            # what a person reads: a curve (degree 2 or 3), not a line
            doc["degree"] >= 2
            # z's held-out error at a capture's noise (20 µg), not the bend's (~70 µg)
            and held["compensated"][2] < 1.5 * NOISE_G * 1e3
            and held["uncompensated"][2] > 2.0 * held["compensated"][2]
            # the model follows the bend over the span within one capture's noise
            and float(np.max(np.abs(change - truth))) < NOISE_G)
    assert sum(good) >= 4, good


def test_the_text_report_names_the_folds_and_what_the_g_error_is(tmp_path, capsys):
    out, _ = _calibrate(tmp_path, _log(seed=0), capsys, json_out=False)
    assert "chosen by held-out error (RMS of held-out captures x/y/z, mg): d=0: " in out
    assert "held-out RMS per axis x, y, z (mg)" in out
    assert "equal temperature blocks (interior blocks alternately held out, the two ends " \
           "always fitted" in out
    # The |g| error is said to be Eq. 9 in mg, and not a figure of the fit: one orientation
    # does not identify the constant bias or scale it contains.
    line = next(ln for ln in out.splitlines() if ln.startswith("|g| error"))
    assert "mg" in line and "not a figure of the fit" in line and "bz, sx, sy, sz" in line


def test_a_straight_warmup_gets_degree_1_on_every_axis(tmp_path, capsys):
    out, _ = _calibrate(tmp_path, _log(seed=3, rest_s=120, heat_s=600, slope_g_per_c=50e-6),
                        capsys, json_out=True)
    doc = json.loads(out)
    assert doc["degree"] == 1, doc["degree_selection"]


def test_a_warmup_with_no_change_fits_nothing(tmp_path, capsys):
    # A gain beyond its standard error by chance is possible: 4 logs of 5 with nothing
    # fitted, and never more than a line fitted to noise.
    docs = [json.loads(_calibrate(tmp_path, _log(seed=seed, bend_g=0.0), capsys,
                                  json_out=True)[0]) for seed in range(10, 15)]
    assert sum(d["degree"] == 0 and d["fitted"] == {} for d in docs) >= 4, \
        [d["degree_selection"] for d in docs]
    assert all(d["degree"] <= 1 for d in docs), [d["degree"] for d in docs]


def test_an_axis_that_does_not_change_is_not_compensated(tmp_path, capsys):
    # z bends; x and y are flat. The degree is chosen on the three axes together, but an
    # axis whose own held-out error is no lower with it keeps no change: its report line
    # never shows "compensated" above "uncompensated", and its bias is held, with why.
    flat_held = 0
    for seed in range(5):
        out, model_path = _calibrate(tmp_path, _log(seed=seed), capsys, json_out=True)
        doc = json.loads(out)
        held = doc["heldout_rms_mg_xyz"]
        assert all(c <= u for c, u in zip(held["compensated"], held["uncompensated"],
                                          strict=True)), held
        assert "bz" in doc["fitted"]
        choice = doc["axis_choice"]
        assert choice["bz"]["degree"] == doc["degree"] >= 1
        model = load_model(model_path)
        T = np.linspace(LO_C + 0.1, HI_C - 0.1, 9)
        for k, name in enumerate(("bx", "by")):
            if choice[name]["degree"] == 0:
                flat_held += 1
                assert name not in doc["fitted"]
                assert "no change with temperature above the noise on this axis" \
                    in doc["held"][name]
                assert np.ptp(model.params_vector_at(T)[:, k]) == 0.0
                assert any(n.startswith(f"{name}: degree 0") for n in doc["notes"])
    assert flat_held >= 6, flat_held  # of the 10 flat axes


def test_axes_that_all_change_keep_the_joint_model(tmp_path, capsys):
    out, _ = _calibrate(tmp_path, _log(seed=3, rest_s=120, heat_s=600, slope_g_per_c=50e-6),
                        capsys, json_out=True)
    doc = json.loads(out)
    assert [c["degree"] for c in doc["axis_choice"].values()] == [doc["degree"]] * 3
    assert set(doc["fitted"]) == {"bx", "by", "bz"}


def _z_only_heat_cool(seed: int, minutes: float = 30.0) -> dict[str, np.ndarray]:
    """1-s mean rows of a board at rest, z up: heated from 20 °C toward 30 °C (τ 5 min) for
    half the log, then cooling toward 20 °C, so dT/dt is not a function of T. z's bias is
    a cubic in T plus a rate term 60 µg per °C/min; x and y do not change at all."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(minutes * 60), dtype=float)
    t_off = 0.5 * t[-1]
    hot = 20.0 + 10.0 * (1.0 - np.exp(-t / 300.0))
    at_off = 20.0 + 10.0 * (1.0 - np.exp(-t_off / 300.0))
    die = np.where(t <= t_off, hot, 20.0 + (at_off - 20.0) * np.exp(-(t - t_off) / 300.0))
    rate_c_per_min = np.gradient(die, t) * 60.0
    u = (die - 25.0) / 5.0
    acc = np.tile([0.0, 0.0, 1.0], (t.size, 1))
    acc[:, 2] += 60e-6 * u ** 3 + 40e-6 * u + 60e-6 * rate_c_per_min
    acc += rng.normal(0.0, NOISE_G, acc.shape)
    sd = np.full(t.size, NOISE_G * 7.0)
    return {"t_s": t, "sensor_c": die + rng.normal(0.0, 0.002, t.size),
            "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2],
            "sd_x": sd, "sd_y": sd, "sd_z": sd, "n": np.full(t.size, 50.0)}


def test_flat_axes_do_not_take_the_model_another_axis_needs(tmp_path, capsys):
    # z needs a cubic and a rate term; x and y have no change at all. The model is chosen
    # on the three axes together, but whether an axis changes is its own question: the
    # joint model must lower that axis' own held-out error beyond the gain's standard
    # error, or the axis is held. (Kept where its own held-out error was merely no higher,
    # a flat axis took a model of a change on 15 of 80 of seeds 0-39, 9 with z's rate term,
    # 2 of them in seeds 0-9.)
    for seed in range(10):
        out, model_path = _calibrate(tmp_path, _z_only_heat_cool(seed), capsys, json_out=True)
        doc = json.loads(out)
        choice = doc["axis_choice"]
        assert choice["bz"] == {**choice["bz"], "degree": 3, "rate_term": True}, choice
        gain = doc["rate_term"]["gain_ug_per_c_per_min"]
        assert abs(gain[2][0] - 60.0) < 3.0, gain
        for k, name in enumerate(("bx", "by")):
            assert (choice[name]["degree"], choice[name]["rate_term"]) == (0, False), \
                (seed, choice)
            assert name not in doc["fitted"] and "on this axis" in doc["held"][name]
            assert gain[k] == [0.0] * len(gain[k])
            model = load_model(model_path)
            T = np.linspace(*model.valid_c, 9)  # type: ignore[misc]
            assert np.ptp(model.params_vector_at(T)[:, k]) == 0.0
