"""Continuous-temperature (ramp) fit and its calibrate dispatch (calibration/continuous.py)."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
import pytest

from calibration import sfem
from calibration.cli import run_calibrate, run_compensate
from calibration.continuous import fit_continuous
from calibration.errors import CalibrationError, NotIdentifiable
from calibration.model_file import load_model
from calibration.plateaus import segment_recording
from calibration.recording import Recording, write_recording
from calibration.temperature_conditioning import condition_continuous
from simulators.ramp_sim import RampProfile, RampRun, ramp_twin_sensors, simulate_ramp
from simulators.truth import SensorTruth

SHORT = RampProfile(start_c=-20.0, peak_c=40.0, end_c=20.0, rate_c_per_min=1.0)
HELDOUT_C = (-15.0, 5.0, 25.0, 35.0)


@pytest.fixture(scope="module")
def ramp() -> RampRun:
    truths, taus = ramp_twin_sensors(1, 5, rate_ug_per_c_per_min=20.0, hysteresis_ug=15.0)
    return simulate_ramp(truths, taus, SHORT, seed=6, temp_row_noise_c=0.1, temp_lsb_c=0.11)[0]


def heldout_ratio(model: object, truth: SensorTruth, seed: int = 9) -> float:
    """RMS vector error of the model over the noise-limited oracle (true parameters at the
    true die temperature) on fresh static readings at HELDOUT_C, 60 random orientations each."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(60 * len(HELDOUT_C), 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    die = np.repeat(HELDOUT_C, 60)
    base = SensorTruth(coeffs=truth.coeffs, temp_offset_c=truth.temp_offset_c)
    raw = base.ideal_raw_g(v, die) + rng.normal(size=v.shape) * base.sample_sd_g() / np.sqrt(200)
    cal = model.compensate(raw, die + base.temp_offset_c)  # type: ignore[attr-defined]
    oracle = sfem.forward(base.params_vector_at(die), raw)
    return float(np.sqrt(np.sum((cal - v) ** 2) / np.sum((oracle - v) ** 2)))


def _calibrate(rec_path: Path, out: Path, **kw: object) -> int:
    ns = argparse.Namespace(recording=str(rec_path), output=str(out), json=False,
                            report_dir=None, method=None)
    for k, v in kw.items():
        setattr(ns, k, v)
    return run_calibrate(ns)


def test_the_continuous_fit_recovers_truth_within_noise(ramp: RampRun) -> None:
    fit = fit_continuous(ramp.recording, segment_recording(ramp.recording))
    assert fit.model.method == "continuous" and fit.model.identifiable.all()
    assert heldout_ratio(fit.model, ramp.truth) < 1.10
    lo, hi = fit.model.valid_c  # the die temperatures covered (±1 °C)
    assert lo == pytest.approx(ramp.die_c.min() + ramp.truth.temp_offset_c, abs=1.2)
    assert hi == pytest.approx(ramp.die_c.max() + ramp.truth.temp_offset_c, abs=1.2)
    k_true = ramp.truth.effects[0].k_g_per_c_per_s / 60.0 * 1e6  # µg per °C/min
    h_true = ramp.truth.effects[1].h_g * 1e6
    k = np.array(fit.report["rate_gain_ug_per_c_per_min"]["value"])
    h = np.array(fit.report["hysteresis_ug"]["value"])
    k_se = np.array(fit.report["rate_gain_ug_per_c_per_min"]["stderr"])
    assert np.all(np.abs(k + h - (k_true + h_true)) < 5 * k_se + 3.0)  # their sum at 1 °C/min


def test_calibrate_on_a_ramp_exits_0_with_a_model_near_the_noise(
        ramp: RampRun, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    src, out = tmp_path / "ramp.csv", tmp_path / "model.json"
    write_recording(src, ramp.recording)
    assert _calibrate(src, out) == 0
    text = capsys.readouterr().out
    assert "continuous temperature (ramp)" in text and "Band (°C)" in text
    assert "-20..-10" in text and "identified: rate sensitivity k" in text
    model = load_model(out)
    assert model.method == "continuous"
    assert heldout_ratio(model, ramp.truth) < 1.10
    comp = tmp_path / "comp.csv"
    # each row's own reading: the default causal filter overshoots the die at the turnaround
    ns = argparse.Namespace(model=str(out), recording=str(src), output=str(comp),
                            extrapolate=False, raw_temperature=True)
    assert run_compensate(ns) == 0
    assert "cx" in comp.read_text().splitlines()[0]


def test_calibrate_json_reports_bands_and_legs(ramp: RampRun, tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    src = tmp_path / "ramp.csv"
    write_recording(src, ramp.recording)
    assert _calibrate(src, tmp_path / "m.json", json=True) == 0
    doc = json.loads(capsys.readouterr().out)
    both = [b for b in doc["bands"] if b["legs"] is not None]
    assert both and all(b["band_c"][0] >= 10.0 for b in both)  # 20..40 °C was crossed both ways
    assert all(len(b["legs"]["difference_se_ug"]) == 3 for b in both)
    assert doc["segmentation"]["continuous_rows"] > 0.9 * doc["rows"]


def test_a_ramp_over_too_few_orientations_is_calibrated_only_as_far_as_it_goes(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Three orientations identify no SFEM: the one gate (calibration/gate.py) makes it a
    warm-up (each axis' bias change with temperature), says so and names what it held."""
    truths, taus = ramp_twin_sensors(1, 2)
    schedule = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    run = simulate_ramp(truths, taus, SHORT, seed=3, schedule=schedule)[0]
    src, out = tmp_path / "three.csv", tmp_path / "m.json"
    write_recording(src, run.recording)
    assert _calibrate(src, out) == 0
    text = capsys.readouterr().out
    assert "3 distinct orientation(s)" in text and "calibrated as a warm-up" in text
    assert "misalignment held" in text
    assert json.loads(out.read_text())["mode"] == "warmup"
    # The continuous fit itself never fits them as an SFEM.
    with pytest.raises(NotIdentifiable, match="only 3 distinct orientation"):
        fit_continuous(run.recording, segment_recording(run.recording))


def test_a_one_way_ramp_says_rate_sensitivity_was_not_identified() -> None:
    truths, taus = ramp_twin_sensors(1, 4)
    one_way = RampProfile(start_c=-20.0, peak_c=40.0, end_c=40.0)
    run = simulate_ramp(truths, taus, one_way, seed=5)[0]
    fit = fit_continuous(run.recording, segment_recording(run.recording))
    assert fit.report["rate_gain_ug_per_c_per_min"] is None
    assert any("one way only" in s for s in fit.report["identified"]["not_identified"])


def test_per_row_conditioning_averages_a_noisy_quantised_channel_on_a_ramp() -> None:
    t = np.arange(600) * 15.2
    die = -40.0 + t / 60.0  # 1 °C/min
    rng = np.random.default_rng(3)
    read = np.round((die + rng.normal(0, 0.1, t.size)) / 0.11) * 0.11
    cond = condition_continuous(t, read, np.full(t.size, -1))
    inner = slice(40, -40)  # away from the run's ends, where the window is one-sided
    assert np.sqrt(np.mean((cond.row_c - die)[inner] ** 2)) < 0.04  # raw: ~0.105 °C
    # the rate's noise × a 20 µg per °C/min rate gain: < 1 µg per row
    assert np.sqrt(np.mean((cond.row_rate_c_per_min[inner] - 1.0) ** 2)) < 0.04


def test_a_short_soak_whose_steps_still_move_is_fitted_within_noise_either_way() -> None:
    # 20 min soaks, die τ = 600 s: the die still moves ~0.6 °C over each step's positions.
    # At a held setpoint the steps are soaks whose die follows the step's line in time
    # (calibration/plateaus.py): steps, fitted jointly at the rows' own temperatures.
    # Declared by step numbers alone they are not plateaus: fitted continuously, and
    # steps 10 °C apart must still spread over the folds. Both within noise.
    from calibration.fitting import fit
    from simulators.campaign_sim import RigPhysics, simulate_campaign

    truth = SensorTruth.adxl355_typical(12)
    rec = simulate_campaign(truth, (-20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0), soak_min=20.0,
                            seed=13, physics=RigPhysics(die_tau_s=600.0))
    soaks = fit(rec)
    assert (soaks.kind, soaks.method) == ("sfem", "joint")
    assert heldout_ratio(soaks.model, truth) < 1.10  # measured 1.04
    steps_only = Recording.from_columns({k: v for k, v in rec.columns.items()
                                         if k != "setpoint_c"})
    seg = segment_recording(steps_only)
    assert seg.continuous_rows > 0.5 * len(rec)
    moving = fit_continuous(steps_only, seg)
    assert moving.model.degree >= 2
    assert heldout_ratio(moving.model, truth) < 1.10  # measured 1.03


def test_a_mixed_recording_reports_its_soaks_as_steps(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    truths, taus = ramp_twin_sensors(1, 7)
    mixed = RampProfile(start_c=-20.0, peak_c=40.0, end_c=20.0, edge_hold_min=30.0)
    run = simulate_ramp(truths, taus, mixed, seed=8)[0]
    src = tmp_path / "mixed.csv"
    write_recording(src, run.recording)
    assert _calibrate(src, tmp_path / "m.json", json=True) == 0
    doc = json.loads(capsys.readouterr().out)
    temps = sorted(p["temperature_c"] - run.truth.temp_offset_c for p in doc["plateaus"])
    assert temps and abs(temps[0] + 20.0) < 0.5 and abs(temps[-1] - 40.0) < 0.5
    assert all(p["rows"] >= 5 and p["rmse_after_mg"] < 0.03 for p in doc["plateaus"])
    assert doc["segmentation"]["continuous_rows"] > 0


def test_a_continuous_fit_over_few_rows_lowers_its_degree_or_refuses_with_the_reason(
        ramp: RampRun) -> None:
    """A few rows on no plateau (a short soak's campaign): a degree whose held-out folds
    would leave fewer residuals than coefficients is not tried; when not even degree 1 can
    be chosen that way, the refusal says so and how to record data that fits."""
    rec = ramp.recording
    few = rec.subset(np.arange(0, len(rec), len(rec) // 14)[:14])
    fit = fit_continuous(few, segment_recording(few))
    assert fit.model.method == "continuous"
    assert max(int(d) for d in fit.model.provenance["degree_heldout_rms_ug"]) < 3
    fewer = rec.subset(np.arange(0, len(rec), len(rec) // 10)[:10])
    with pytest.raises(CalibrationError, match=r"10 rows on no temperature plateau are too "
                       r"few .* soak until the die settles"):
        fit_continuous(fewer, segment_recording(fewer))


def _two_holds_and_a_few_ramp_rows() -> Recording:
    """A sparse ramp like a loaded engine's: most rows at the two held temperatures (−20 and
    40 °C), a few while the die moves; leaving out a held temperature's fold leaves rows
    that pin a low-degree polynomial and no higher one."""
    truths, taus = ramp_twin_sensors(1, 5, rate_ug_per_c_per_min=20.0, hysteresis_ug=15.0)
    held = RampProfile(start_c=-20.0, peak_c=40.0, end_c=20.0, edge_hold_min=120.0)
    run = simulate_ramp(truths, taus, held, seed=6, temp_row_noise_c=0.1, temp_lsb_c=0.11)[0]
    at_hold = np.flatnonzero((np.abs(run.die_c + 20.0) < 0.5) | (np.abs(run.die_c - 40.0) < 0.5))
    moving = np.setdiff1d(np.arange(len(run.recording)), at_hold)
    # every 7th held row: 7 is prime to the 24 positions of the sweep, so each is visited
    rows = np.union1d(at_hold[::7], moving[::15])
    return run.recording.subset(rows)


def test_a_degree_a_fold_does_not_determine_is_not_judged_and_the_note_says_so() -> None:
    """Held-out error is computed only from folds whose training rows determine the
    degree's coefficients (the design's condition number within CONDITION_LIMIT, checked
    before any refit): the search stops at the first degree one fold does not determine,
    the degree is chosen below it, and the notes name the degree, the fold and why."""
    from calibration.continuous import CONDITION_LIMIT

    rec = _two_holds_and_a_few_ramp_rows()
    fit = fit_continuous(rec, segment_recording(rec))
    notes = [n for n in fit.model.notes if "not judged" in n]
    assert len(notes) == 1, fit.model.notes
    m = re.match(r"degree (\d) not judged: fold (\d) of 5's training rows \((\d+) of "
                 rf"{len(rec)}\) do not determine its coefficients \(their design's "
                 r"condition number ([0-9.e+]+) is above 1e\+08\); ", notes[0])
    assert m, notes[0]
    stopped = int(m.group(1))
    assert float(m.group(4)) > CONDITION_LIMIT
    assert fit.model.degree < stopped
    judged = sorted(int(d) for d in fit.model.provenance["degree_heldout_rms_ug"])
    assert judged == list(range(1, stopped))  # none at or above the stop
    assert notes[0] in fit.report["notes"]


def test_a_fold_refit_that_does_not_converge_rules_its_degree_out(
        ramp: RampRun, monkeypatch: pytest.MonkeyPatch) -> None:
    """A fold's Levenberg–Marquardt refit that stops unconverged gives no held-out error:
    its degree is not judged (nor any above it) and the note says which fold and why."""
    from types import SimpleNamespace

    from calibration import continuous

    real = continuous._refit_without

    def refit(prob: object, train: np.ndarray, q: np.ndarray, sol: object,
              n_coef: int) -> tuple[np.ndarray, object]:
        if n_coef == 4:  # degree 3: the LM ran out of evaluations
            return q, SimpleNamespace(success=False, nfev=5400, message="The maximum "
                                      "number of function evaluations is exceeded.")
        return real(prob, train, q, sol, n_coef)  # type: ignore[arg-type]

    monkeypatch.setattr(continuous, "_refit_without", refit)
    fit = fit_continuous(ramp.recording, segment_recording(ramp.recording))
    assert sorted(fit.model.provenance["degree_heldout_rms_ug"]) == ["1", "2"]
    assert fit.model.degree in (1, 2)
    assert any(n.startswith("degree 3 not judged: fold 1 of 5's refit did not converge "
                            "(Levenberg–Marquardt stopped after 5400 evaluations: The "
                            "maximum number of function evaluations is exceeded); the "
                            "degree is chosen among 1…2") for n in fit.model.notes), \
        fit.model.notes


def test_when_not_even_degree_1_is_judged_it_is_fitted_without_a_held_out_score(
        ramp: RampRun, monkeypatch: pytest.MonkeyPatch) -> None:
    from calibration import continuous

    def not_determined(J: np.ndarray) -> float:
        return 1e12  # every fold's design beyond CONDITION_LIMIT, from degree 1

    monkeypatch.setattr(continuous, "_design_condition", not_determined)
    fit = fit_continuous(ramp.recording, segment_recording(ramp.recording))
    assert fit.model.degree == 1
    assert fit.model.provenance["degree_heldout_rms_ug"] == {}
    notes = [n for n in fit.model.notes if "not judged" in n]
    assert len(notes) == 1 and re.fullmatch(
        r"degree 1 not judged: fold 1 of 5's training rows \(\d+ of "
        rf"{len(ramp.recording)}\) do not determine its coefficients \(their design's "
        r"condition number 1\.0e\+12 is above 1e\+08\); degree 1 is used without a "
        r"held-out score", notes[0]), notes
