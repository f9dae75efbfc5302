"""``diagnose --against`` holds the shared level as a whole (docs/diagnosis.md §9).

Its verdict is the union of the coefficient-shift test, the refit diagnosis and (a twin
with a die lag on a chamber-only recording) the rig check; each at α would flag an
unchanged sensor with probability up to 3α. Each runs at α / (tests run).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calibration.discrepancy.against import diagnose_against, verdict_level
from calibration.discrepancy.level import ALPHA, N_NULL
from calibration.discrepancy.twin_file import Twin
from calibration.recording import Recording
from calibration.thermal import fit_campaign
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


@pytest.mark.parametrize(("refit", "rig", "k"), [(False, False, 1), (True, False, 2),
                                                 (False, True, 2), (True, True, 3)])
def test_alpha_is_split_over_the_tests_the_verdict_runs(refit, rig, k):
    level = verdict_level(ALPHA, N_NULL, refit=refit, rig=rig)
    assert len(level["tests"]) == k
    assert level["alpha_each"] * k == pytest.approx(ALPHA)
    if refit:
        # the refit diagnosis splits its share over its two tests: its bootstrap resolves
        # that (p = 1/(B + 1) ≤ α_each / 2), and never has fewer replicates than asked
        assert 1.0 / (level["n_null_refit"] + 1) <= level["alpha_each"] / 2
        assert level["n_null_refit"] >= N_NULL
    else:
        assert level["n_null_refit"] is None


def test_the_refit_diagnosis_and_the_shift_run_at_half_the_level_and_say_so():
    truth = SensorTruth.adxl355_typical(seed=21)
    model = fit_campaign(simulate_campaign(truth, ONE_WAY, seed=101, soak_min=30)).model
    d = diagnose_against(simulate_campaign(truth, ONE_WAY, seed=102, soak_min=30),
                         Twin(model), n_null=40)
    out = d.to_dict()
    assert out["level"]["tests"] == ["parameter_shift", "refit_diagnosis"]
    assert out["refit_diagnosis"]["null"]["alpha"] == pytest.approx(ALPHA / 2)
    # 40 replicates cannot resolve α/4: the refit diagnosis gets the number that does
    assert out["refit_diagnosis"]["null"]["n_null"] == out["level"]["n_null_refit"]
    assert out["level"]["n_null_refit"] > 40
    assert d.reason.endswith(f"each test at α/2 = {ALPHA / 2:.3g}")
    assert f"each test at α/2 = {ALPHA / 2:.3g}" in d.report()


def test_the_recorded_noise_is_a_floor_of_the_shift_sigma():
    """σ_δ is scaled up by χ²/dof above 1, never down: a recording whose sd columns say
    its noise is twice as large gets twice the σ (scaled by χ²/dof it came out the same,
    and a pessimistic sd/√n then tightened the temperature coefficients' σ)."""
    truth = SensorTruth.adxl355_typical(seed=21)
    model = fit_campaign(simulate_campaign(truth, ONE_WAY, seed=101, soak_min=30)).model
    twin = Twin(replace(model, coeff_stderr=None))  # σ of δ from the recording alone
    rec = simulate_campaign(truth, ONE_WAY, seed=102, soak_min=30)
    loud = Recording.from_columns({k: v * 2.0 if k.startswith("sd_") else v
                                   for k, v in rec.columns.items()})
    sd = [{(c["parameter"], c["power"]): c["sd"] for c in
           diagnose_against(r, twin, refit=False).shift["coefficients"]} for r in (rec, loud)]
    ratio = np.array([sd[1][k] / sd[0][k] for k in sd[0]])
    assert np.all(ratio > 1.7) and np.all(ratio < 2.3)
