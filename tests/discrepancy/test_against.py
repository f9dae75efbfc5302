"""``diagnose --against``: the given model held fixed (docs/diagnosis.md §9)."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from calibration.discrepancy import diagnose
from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_file import Twin, load_model_or_twin
from calibration.model_file import save_model
from calibration.recording import Recording, write_recording
from calibration.thermal import fit_campaign
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


def record(truth: SensorTruth, seed: int) -> Recording:
    return simulate_campaign(truth, ONE_WAY, seed=seed, soak_min=30)


def norm_only(rec: Recording) -> Recording:
    return Recording.from_columns({k: v for k, v in rec.columns.items()
                                   if not k.startswith("ref_")})


@pytest.fixture(scope="module")
def sensor():
    truth = SensorTruth.adxl355_typical(seed=21)
    model = fit_campaign(record(truth, 101)).model
    return truth, model


def test_same_sensor_fresh_recording_is_consistent(sensor):
    truth, model = sensor
    d = diagnose_against(record(truth, 102), Twin(model), refit=False)
    assert d.mismatch is False
    assert not d.shift["significant"] and d.findings == []
    assert d.rmse_given_ug < 1.5 * d.noise_ug


def test_aged_bias_is_a_parameter_shift_with_sigma(sensor):
    truth, model = sensor
    aged = replace(truth, coeffs=truth.coeffs.copy())
    aged.coeffs[1, 0] += 0.4e-3  # y bias aged 0.4 mg
    d = diagnose_against(record(aged, 103), Twin(model), refit=False)
    assert d.mismatch is True
    f = d.findings[0]
    assert f["effect"] == "parameter_shift" and f["axes"] == ["y"]
    assert list(f["parameters"]) == ["d_by_ug"]
    assert abs(f["parameters"]["d_by_ug"] - 400.0) < 5 * f["parameter_sd"]["d_by_ug"]
    assert "y bias moved" in f["explanation"]
    assert d.heldout["rmse_corrected_ug"] < 0.5 * d.heldout["rmse_given_ug"]


def test_model_of_another_sensor_is_a_mismatch(sensor):
    _, model = sensor
    other = SensorTruth.adxl355_typical(seed=77)
    d = diagnose_against(record(other, 104), Twin(model), refit=False)
    assert d.mismatch is True and d.rmse_given_ug > 1000.0
    assert d.heldout["rmse_corrected_ug"] < 0.05 * d.heldout["rmse_given_ug"]


def test_norm_mode_against(sensor):
    truth, model = sensor
    null = diagnose_against(norm_only(record(truth, 105)), Twin(model), refit=False)
    assert null.mode == "norm" and null.mismatch is False
    aged = replace(truth, coeffs=truth.coeffs.copy())
    aged.coeffs[0, 0] += 1e-3
    d = diagnose_against(norm_only(record(aged, 106)), Twin(model), refit=False)
    assert d.mismatch is True and "d_bx_ug" in d.shift["parameters"]


def test_too_few_rows_cannot_judge(sensor):
    truth, model = sensor
    rec = record(truth, 107)
    small = Recording.from_columns({k: v[:3] for k, v in rec.columns.items()})
    d = diagnose_against(small, Twin(model), refit=False)
    assert d.mismatch is None and d.to_dict()["mismatch"] is None
    assert "too few" in d.reason
    with np.errstate(all="raise"):
        plain = diagnose(Recording.from_columns({k: v[:1] for k, v in rec.columns.items()}))
    assert plain.mismatch is None and plain.to_dict()["verdict"] == "cannot judge"


def test_cli_against_writes_a_twin_that_loads(sensor, tmp_path, capsys):
    from calibration.discrepancy.cli import run_diagnose

    truth, model = sensor
    aged = replace(truth, coeffs=truth.coeffs.copy())
    aged.coeffs[4, 0] += 200e-6  # y scale factor moved 200 ppm
    rec_path, model_path, twin_path = (tmp_path / "r.csv", tmp_path / "m.json",
                                       tmp_path / "twin.json")
    write_recording(rec_path, record(aged, 108))
    save_model(model_path, model)
    args = SimpleNamespace(recording=str(rec_path), model=None, json=True, report_dir=None,
                           seed=0, n_null=20, against=str(model_path),
                           write_twin=str(twin_path))
    assert run_diagnose(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mismatch"] is True and out["findings"][0]["effect"] == "parameter_shift"
    assert "d_sy_ppm" in out["findings"][0]["parameters"]
    twin = load_model_or_twin(twin_path)
    assert twin.model.coeffs[4, 0] - model.coeffs[4, 0] == pytest.approx(200e-6, abs=20e-6)
    # The corrected twin, held against the same recording, no longer differs in that parameter.
    again = diagnose_against(Recording.from_columns(dict(record(aged, 109).columns)), twin,
                             refit=False)
    assert "d_sy_ppm" not in again.shift["parameters"]


def test_cli_against_bad_file_exit_2(tmp_path, capsys):
    from calibration.discrepancy.cli import run_diagnose

    rec_path = tmp_path / "r.csv"
    write_recording(rec_path, record(SensorTruth.adxl355_typical(seed=1), 5))
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "nope"}')
    args = SimpleNamespace(recording=str(rec_path), model=None, json=True, report_dir=None,
                           seed=0, n_null=20, against=str(bad), write_twin=None)
    assert run_diagnose(args) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "bad.json" in err and "format" in err


def test_five_setpoints_are_held_out_by_visit_groups_as_diagnose_does(sensor):
    """With five plateaus and the given model's cubic, holding out an interior plateau
    would leave the cubic fitted exactly through the other four: ``--against`` then
    holds out interleaved visit groups, the fold rule of ``diagnose`` (heldout.py), and
    the shift still predicts the held-out visits."""
    truth, model = sensor
    assert model.coeffs.shape[1] == 4  # a cubic in temperature
    aged = replace(truth, coeffs=truth.coeffs.copy())
    aged.coeffs[1, 0] += 0.4e-3
    five = simulate_campaign(aged, [-40.0, -15.0, 10.0, 35.0, 60.0], seed=107, soak_min=30)
    d = diagnose_against(five, Twin(model), refit=False)
    assert d.heldout["scheme"].startswith("leave-one-visit-group-out")
    assert d.heldout["rmse_corrected_ug"] < 0.5 * d.heldout["rmse_given_ug"]
    eleven = diagnose_against(record(aged, 108), Twin(model), refit=False)
    assert eleven.heldout["scheme"] == "leave-one-step-out (interior steps)"
