"""Wrong campaign recordings a lab engineer might give (issues 20 and 22; docs/benchmarks.md,
"Wrong campaign recordings"): each is refused by ``calibrate`` with its own cause and fix,
and ``diagnose`` answers "cannot judge" with the same reason (calibration/gate.py,
``check_recording``).

Every recording is built here: Table 1's 24 positions with reference vectors at three
temperature steps, a sensor 20 mg off on x and 1 % off in scale on y, 200-sample means."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calibration import cli
from calibration.recording import Recording, write_recording
from calibration.schedules import table1

Columns = dict[str, np.ndarray]


def _campaign(seed: int = 1, setpoints_c: tuple[float, ...] = (-20.0, 20.0, 60.0)
              ) -> Columns:
    """Soaks (−20, 20, 60 °C), 24 positions each, reference vectors in g."""
    rng = np.random.default_rng(seed)
    refs = table1()
    rows: dict[str, list[float]] = {k: [] for k in (
        "t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position")}
    raw, ref = [], []
    t = 0.0
    for s, sp in enumerate(setpoints_c):
        t += 3600.0
        for p, r in enumerate(refs):
            t += 15.0
            bias = np.array([0.020 + 2e-5 * sp, -0.010, 0.015 - 1e-5 * sp])
            raw.append(r * np.array([1.0, 1.01, 0.995]) + bias + rng.normal(0, 1e-5, 3))
            ref.append(r)
            rows["t_s"].append(t)
            rows["step"].append(s)
            rows["setpoint_c"].append(sp)
            rows["chamber_c"].append(sp + rng.normal(0, 0.02))
            rows["sensor_c"].append(sp + 3.0 + rng.normal(0, 0.01))
            rows["position"].append(p)
    cols = {k: np.asarray(v, float) for k, v in rows.items()}
    raw_g, ref_g = np.asarray(raw), np.asarray(ref)
    n = len(raw_g)
    cols.update(ax=raw_g[:, 0], ay=raw_g[:, 1], az=raw_g[:, 2], ref_x=ref_g[:, 0],
                ref_y=ref_g[:, 1], ref_z=ref_g[:, 2], n=np.full(n, 200.0),
                sd_x=np.full(n, 1.4e-4), sd_y=np.full(n, 1.4e-4), sd_z=np.full(n, 1.5e-4))
    return cols


def _run(tmp_path: Path, cols: Columns, capsys: pytest.CaptureFixture[str]
         ) -> tuple[str, str]:
    """``calibrate`` (must refuse: exit 2, one line, no model) and ``diagnose --json``
    (must answer "cannot judge"): the line a person reads and diagnose's reason."""
    src, out = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, cols)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(out))) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert not out.exists()
    doc = _cannot_judge(src, capsys)
    assert doc["mismatch"] is None
    assert doc["reason"] in err  # the same reason as calibrate's
    return err, doc["reason"]


def _cannot_judge(src: Path, capsys: pytest.CaptureFixture[str]) -> dict:
    """``diagnose --json`` on ``src``: exit 0 with the verdict "cannot judge"; its JSON."""
    args = SimpleNamespace(recording=str(src), output=None, json=True, model=None,
                           n_null=None, against=None, write_twin=None, report_dir=None,
                           seed=None)
    assert cli.run_diagnose(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["verdict"] == "cannot judge"
    return doc


def test_the_unperturbed_campaign_is_calibrated(tmp_path: Path) -> None:
    src, out = tmp_path / "rec.csv", tmp_path / "model.json"
    write_recording(src, _campaign())
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(out))) == 0
    assert out.exists()


def test_a_sensor_channel_in_fahrenheit_is_refused_naming_the_unit(tmp_path, capsys) -> None:
    # main: exit 0, a model "valid for 1.4 .. 145 °C" in °F (1.4 mg off the right one)
    cols = _campaign()
    cols["sensor_c"] = cols["sensor_c"] * 1.8 + 32.0
    err, _ = _run(tmp_path, cols, capsys)
    assert "sensor_c rises 1.8 °C per °C of setpoint_c" in err
    assert "sensor_c looks like °F" in err
    assert "write every _c column in °C" in err


def test_a_chamber_channel_in_fahrenheit_is_refused_by_compensate_too(tmp_path,
                                                                      capsys) -> None:
    cols = _campaign()
    good, model = tmp_path / "good.csv", tmp_path / "good.json"
    write_recording(good, cols)
    assert cli.run_calibrate(SimpleNamespace(recording=str(good), output=str(model))) == 0
    capsys.readouterr()
    cols["chamber_c"] = cols["chamber_c"] * 1.8 + 32.0
    _run(tmp_path, cols, capsys)
    out = tmp_path / "out.csv"
    assert cli.run_compensate(SimpleNamespace(
        model=str(model), recording=str(tmp_path / "rec.csv"), output=str(out))) == 2
    err = capsys.readouterr().err
    assert "chamber_c looks like °F" in err and "nothing written" in err
    assert not out.exists()


def test_a_flipped_reference_axis_is_named_not_blamed_on_orientations(tmp_path,
                                                                      capsys) -> None:
    # main: "the fitted scale sz = -0.99 … is not physical …: record at least 10 distinct
    # orientations": the wrong cause
    cols = _campaign()
    cols["ref_z"] = -cols["ref_z"]
    err, _ = _run(tmp_path, cols, capsys)
    assert "az ≈ −ref_z" in err and "ref_z has its sign flipped" in err
    assert "distinct orientations" not in err


def test_swapped_reference_axes_are_named(tmp_path, capsys) -> None:
    cols = _campaign()
    cols["ref_x"], cols["ref_y"] = cols["ref_y"].copy(), cols["ref_x"].copy()
    err, _ = _run(tmp_path, cols, capsys)
    assert "ax ≈ +ref_y, ay ≈ +ref_x, az ≈ +ref_z" in err
    assert "ref_x and ref_y are swapped" in err


def test_one_positions_wrong_reference_is_named_with_its_step_and_position(tmp_path,
                                                                           capsys) -> None:
    # main: "the model gives |g| = 0.72 g … average only what was recorded with the sensor
    # still": the wrong cause
    cols = _campaign()
    five, zero = cols["position"] == 5, np.flatnonzero(cols["position"] == 0)[0]
    for k in ("ref_x", "ref_y", "ref_z"):
        cols[k][five] = cols[k][zero]
    err, _ = _run(tmp_path, cols, capsys)
    assert "step 0, position 5 is" in err and "from its reference vector" in err
    assert "(3 reading(s) so)" in err
    assert "a reference written for another position" in err


def test_a_plateau_written_twice_is_refused(tmp_path, capsys) -> None:
    # main: calibrate exit 0 (the plateau counted twice); diagnose "cannot judge: … on no
    # temperature plateau" (the wrong cause)
    cols = _campaign()
    s1 = np.flatnonzero(cols["step"] == 1)
    order = np.r_[np.flatnonzero(cols["step"] <= 1), s1, np.flatnonzero(cols["step"] > 1)]
    dup = {k: v[order] for k, v in cols.items()}
    dup["t_s"] = dup["t_s"] + np.r_[np.zeros(2 * 24), np.full(24 + 24, 2000.0)]
    err, _ = _run(tmp_path, dup, capsys)
    assert "step 1, position 0 repeats the one at" in err
    assert "(24 row(s) repeat an earlier one)" in err
    assert "remove the repeated rows" in err


def test_means_of_few_quantised_samples_may_repeat_when_their_scatter_does_not() -> None:
    """The means of 50 samples of a 0.49 mg-LSB sensor lie on a 9.8 µg grid and do repeat
    (a gen2 ICM-42688 warm-up's 1-s means, 27 s apart): not a block written twice unless
    sd_* repeat as well."""
    from calibration import gate

    cols = _campaign()
    lsb_g = 2.0**-11
    for k, a in enumerate(("ax", "ay", "az")):
        cols[a] = np.round(cols[a] / (lsb_g / 50)) * (lsb_g / 50)
        cols[f"sd_{'xyz'[k]}"] = 4e-4 + 1e-6 * np.arange(len(cols[a]))
    cols["ax"][29], cols["ay"][29], cols["az"][29] = cols["ax"][5], cols["ay"][5], cols["az"][5]
    gate.check_recording(Recording.from_columns(cols))  # the means alone repeat: kept
    for k in ("sd_x", "sd_y", "sd_z"):
        cols[k][29] = cols[k][5]  # the same position, the next step
    with pytest.raises(gate.GateRefusal, match="repeats the one at .* in ax, ay, az and sd_"):
        gate.check_recording(Recording.from_columns(cols))


def test_sd_in_mg_names_the_unit_not_a_moving_sensor_alone(tmp_path, capsys) -> None:
    # main: "no still reading: every row was left out as taken while the sensor moved",
    # nothing about the unit
    cols = _campaign()
    for k in ("sd_x", "sd_y", "sd_z"):
        cols[k] = cols[k] * 1e3
    err, _ = _run(tmp_path, cols, capsys)
    assert "the rows' sd_* (median 0.15 g)" in err
    assert "sd_* written in mg? sd_* are in g" in err


def test_one_steps_readings_from_another_sensor_are_refused_naming_the_step(tmp_path,
                                                                           capsys) -> None:
    # main: exit 0, a model 11 mg (RMS) off the right one, up to 22 mg; diagnose:
    # "mismatch" with not_identifiable and unexplained findings
    cols = _campaign(setpoints_c=(-20.0, 0.0, 20.0, 40.0, 60.0))
    other = cols["step"] == 2
    cols["ax"][other] += 0.020
    cols["az"][other] -= 0.015
    err, _ = _run(tmp_path, cols, capsys)
    assert "the temperature polynomial leaves step" in err
    assert "the sensor's parameters jump between steps (step 2's bias bx is +2" in err
    assert "one step's readings from another sensor or another mounting?" in err


def test_n_too_large_is_not_blamed_on_the_plateaus_alone(tmp_path, capsys) -> None:
    # main: diagnose "cannot judge: … on no temperature plateau" and nothing else: the steps
    # are soaks, but at a stated noise sd/√n of 0.3 µg none is flat enough
    cols = _campaign()
    cols["n"] = cols["n"] * 1000
    src = tmp_path / "rec.csv"
    write_recording(src, cols)
    doc = _cannot_judge(src, capsys)
    assert "at the readings' stated noise sd/√n, 0.3" in doc["reason"]
    assert "or n or sd_* too small?" in doc["reason"]


def test_a_die_far_behind_short_soaks_is_not_a_unit(tmp_path: Path) -> None:
    """The die follows the air, possibly far behind: a campaign whose sensor_c rises a
    fifth as much as its setpoint (soaks too short to settle) is physics, not a unit, and
    is calibrated on the die's own channel; only a channel rising faster than the one it
    follows (°F: 1.8 per °C) is refused."""
    from calibration import gate

    def rec(sensor_c: list[float]) -> Recording:
        n = 12
        return Recording.from_columns({
            "t_s": np.arange(n) * 60.0, "step": np.repeat([0, 1, 2], 4),
            "ax": np.zeros(n), "ay": np.zeros(n), "az": np.ones(n),
            "setpoint_c": np.repeat([20.0, 30.0, 40.0], 4),
            "sensor_c": np.repeat(sensor_c, 4)})

    gate.check_temperature_channels(rec([22.0, 24.0, 26.0]))  # 0.2 °C per °C: no refusal
    hot = rec([68.0, 86.0, 104.0])
    with pytest.raises(gate.GateRefusal, match="sensor_c looks like °F"):
        gate.check_temperature_channels(hot)
