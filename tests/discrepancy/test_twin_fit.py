"""``soakcal twin fit`` and the rig check of ``diagnose --against`` (docs/diagnosis.md §9–10)."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_file import load_model_or_twin
from calibration.discrepancy.twin_fit import fit_twin
from calibration.recording import write_recording
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
TRUTH = SensorTruth.adxl355_typical(seed=5)


def chamber_only(seed: int, tau_s: float, truth: SensorTruth = TRUTH):
    return simulate_campaign(truth, ONE_WAY, seed=seed, soak_min=20,
                             physics=replace(RigPhysics(), die_tau_s=tau_s),
                             temperature_columns=("chamber_c",))


@pytest.fixture(scope="module")
def fitted():
    return fit_twin(chamber_only(1, 900.0))


def test_twin_fit_finds_the_die_lag_and_reaches_the_noise(fitted):
    twin, report = fitted
    # The die history is reconstructed with an assumed 2 °C/min ramp and no air settling:
    # τ comes out within ~10 % of the rig's (docs/diagnosis.md §10).
    assert twin.die_tau_s == pytest.approx(900.0, rel=0.15)
    assert report["worst_plateau_rms_over_noise"] < 1.5
    assert twin.sample_sd_g is not None and twin.samples_per_reading == 200.0


def test_twin_with_a_wrong_die_lag_is_found_and_corrected(fitted):
    twin, _ = fitted
    wrong = replace(twin, die_tau_s=300.0)
    d = diagnose_against(chamber_only(3, 900.0), wrong, refit=False)
    assert d.mismatch is True
    lag = [f for f in d.findings if f["effect"] == "thermal_lag"]
    assert lag and lag[0]["parameters"]["tau_s"] == pytest.approx(twin.die_tau_s, rel=0.05)
    assert d.heldout["rmse_corrected_ug"] < 0.5 * d.heldout["rmse_given_ug"]
    assert d.corrected is not None and d.corrected.die_tau_s == pytest.approx(
        twin.die_tau_s, rel=0.05)


def test_right_twin_is_consistent_with_a_fresh_recording(fitted):
    twin, _ = fitted
    d = diagnose_against(chamber_only(2, 900.0), twin, refit=False)
    assert d.mismatch is False


def test_sim_truth_from_twin_reproduces_the_model(fitted):
    twin, _ = fitted
    truth = SensorTruth.from_twin(twin)
    T = np.array([-40.0, -3.0, 25.0, 60.0])
    np.testing.assert_allclose(truth.params_vector_at(T), twin.model.params_vector_at(T, True),
                               rtol=0, atol=1e-12)
    assert truth.noise_density_ug_rthz == pytest.approx(25.0, rel=0.05)
    # A campaign simulated from the twin (at its own lag) is consistent with the twin.
    sim = chamber_only(7, twin.die_tau_s, truth)
    assert diagnose_against(sim, twin, refit=False).mismatch is False


def test_cli_twin_fit(tmp_path, capsys):
    from calibration.discrepancy.twin_cli import run_twin_fit

    rec_path, out = tmp_path / "r.csv", tmp_path / "twin.json"
    write_recording(rec_path, chamber_only(4, 600.0))
    assert run_twin_fit(SimpleNamespace(recording=str(rec_path), output=str(out),
                                        json=True)) == 0
    report = json.loads(capsys.readouterr().out)
    assert len(report["per_plateau"]) == len(ONE_WAY)
    assert load_model_or_twin(out).die_tau_s == pytest.approx(600.0, rel=0.15)
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,ax\n1,2\n")
    assert run_twin_fit(SimpleNamespace(recording=str(bad), output=str(tmp_path / "no.json"),
                                        json=False)) == 2
    assert not (tmp_path / "no.json").exists()
    assert "\n" not in capsys.readouterr().err.strip()
