"""A twin carries the catalogue effects its recording shows (docs/diagnosis.md §10).

``twin fit`` diagnoses the recording, keeps the effects a new campaign of the sensor meets
again, fits the base to the recording less their output; ``sim`` simulates them and
``diagnose --against`` holds them in the twin's prediction, their coefficients tested
with the twin's own σ beside the base's.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_effects import coefficients
from calibration.discrepancy.twin_file import load_model_or_twin, save_twin
from calibration.discrepancy.twin_fit import fit_twin, report_text
from calibration.errors import ModelFileError
from calibration.recording import Recording, write_recording
from service.cli import main as soakcal
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

SETPOINTS_C = [-40.0, -20.0, 0.0, 20.0, 40.0, 60.0]
K2_X = 150e-6  # g/g²: ~15 σ of a 6-plateau Table 1 campaign's K2


def truth_with(*effects: object) -> SensorTruth:
    truth = SensorTruth.adxl355_typical(seed=5)
    truth.effects = list(effects)
    return truth


def bent(k2_x_per_g: float) -> fx.ScaleNonlinearity:
    return fx.ScaleNonlinearity(k2_per_g=np.array([k2_x_per_g, 0.0, 0.0]), k3_per_g2=np.zeros(3))


def campaign(truth: SensorTruth, seed: int):
    # A balanced position order: under Table 1's fixed order a nonlinearity is not told
    # apart from a turn of the table (docs/diagnosis.md §11).
    return simulate_campaign(truth, SETPOINTS_C, seed=seed, soak_min=30,
                             position_order="balanced", position_order_seed=seed)


@pytest.fixture(scope="module")
def fitted():
    return fit_twin(campaign(truth_with(bent(K2_X)), 1))


def k2_x_ug(effect: dict) -> float:
    return effect["parameters"]["k2_x_ug_per_g2"]


def test_the_twin_carries_the_nonlinearity_and_a_new_campaign_agrees_with_it(fitted):
    twin, report = fitted
    assert [e["effect"] for e in twin.effects] == ["scale_nonlinearity"]
    assert k2_x_ug(twin.effects[0]) == pytest.approx(150.0, abs=8.0)
    text = report_text(report, "twin.json")
    assert "effects carried: scale_nonlinearity" in text
    assert "K2 = 15" in text  # the finding's own sentence, in µg/g²
    # The whole twin (base + effect) reaches the noise on the recording it was fitted to.
    assert report["worst_plateau_rms_over_noise"] < 1.3
    again = campaign(truth_with(bent(K2_X)), 2)
    d = diagnose_against(again, twin)
    assert d.mismatch is False, d.reason
    assert any("part of its prediction" in n for n in d.notes)
    # Without the effect the same sensor is a mismatch: the nonlinearity is "found".
    bare, _ = fit_twin(campaign(truth_with(bent(K2_X)), 1), effects=False)
    d0 = diagnose_against(again, bare)
    assert d0.mismatch is True
    assert "scale_nonlinearity" in [f["effect"] for f in d0.findings]


def test_a_changed_effect_is_named_as_the_twins_effect_that_moved(fitted):
    twin, _ = fitted
    d = diagnose_against(campaign(truth_with(bent(175e-6)), 2), twin)
    assert d.mismatch is True
    assert "the twin's effects moved" in d.reason
    (shift,) = [f for f in d.findings if f["effect"] == "parameter_shift"]
    assert "the twin's scale_nonlinearity differs: k2_x_ug_per_g2 17" in shift["explanation"]
    assert "in the twin" in shift["explanation"]
    moved = [c["parameter"] for c in d.shift["coefficients"] if c["significant"]]
    assert moved == ["scale_nonlinearity.coef[0]"]  # K2 on x, by its place in the twin file
    # The corrected twin carries the effect as this recording has it.
    assert d.corrected is not None
    assert d.corrected.effects[0]["coef"][0] == pytest.approx(175e-6, abs=8e-6)


def test_the_simulated_rig_reproduces_the_twins_effect(fitted):
    twin, _ = fitted
    sim_truth = SensorTruth.from_twin(twin)
    (eff,) = sim_truth.effects
    assert isinstance(eff, fx.ScaleNonlinearity)
    # from the finding's parameters, which are written to 4 significant digits
    assert eff.k2_per_g[0] == pytest.approx(twin.effects[0]["coef"][0], rel=1e-3)
    d = diagnose_against(campaign(sim_truth, 3), twin)
    assert d.mismatch is False, d.reason


def test_an_outlier_is_left_out_of_the_twin_with_why():
    spiked = truth_with(fx.Outlier(size_g=np.array([0.0, 0.0, 400e-6]), rows=(30,)))
    twin, report = fit_twin(campaign(spiked, 4))
    assert twin.effects == []
    (left,) = report["effects_not_carried"]
    assert left["effect"] == "outlier" and "an event of this recording" in left["why"]
    assert "not carried: outlier: an event of this recording" in report_text(report, "t.json")


def test_structure_no_term_names_is_said_not_to_be_in_the_twin():
    from calibration.discrepancy.twin_effects import carried_effects

    class Finding:  # what carried_effects reads of an ``unexplained`` finding
        effect, axes, term_keys = "unexplained", ["z"], set()

    class Diag:
        findings, terms, problem = [Finding()], [], None

    carried, left = carried_effects(Diag())
    assert carried == []
    assert left == [{"effect": "unexplained", "why": "no catalogue term names this structure "
                     "(axis z): the twin does not reproduce it"}]


def test_a_twin_file_keeps_its_effects_and_refuses_one_it_cannot_evaluate(fitted, tmp_path):
    twin, _ = fitted
    path = tmp_path / "twin.json"
    save_twin(path, twin)
    back = load_model_or_twin(path)
    assert back.effects == twin.effects
    assert coefficients(back.effects)[1].size == 6  # K2, K3 per axis, with their σ
    doc = json.loads(path.read_text())
    doc["effects"] = [{"effect": "outlier", "coef": [1e-4]}]
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"effects\[0\]: 'outlier' is not an effect a "
                                             r"twin carries"):
        load_model_or_twin(path)


def test_the_cli_says_what_the_twin_carries(tmp_path, capsys):
    rec = tmp_path / "rec.csv"
    write_recording(rec, campaign(truth_with(bent(K2_X)), 1))
    assert soakcal(["twin", "fit", str(rec), "-o", str(tmp_path / "t.json")]) == 0
    out = capsys.readouterr().out
    assert "effects carried: scale_nonlinearity" in out
    assert soakcal(["twin", "fit", str(rec), "-o", str(tmp_path / "t0.json"),
                    "--no-effects"]) == 0
    assert "effects: not diagnosed (--no-effects)" in capsys.readouterr().out
    assert load_model_or_twin(tmp_path / "t0.json").effects == []


def test_a_twin_effect_the_recording_cannot_feed_is_refused_with_the_reason(fitted, tmp_path,
                                                                           capsys):
    twin, _ = fitted
    vib = {"effect": "vibration_rectification", "theta": None, "coef": [0.01, 0.0, 0.0],
           "coef_sd": [0.001, 0.001, 0.001], "parameters": {}, "parameter_sd": {},
           "explanation": "x output shifts with the vibration power"}
    save_twin(tmp_path / "vib.json", replace(twin, effects=[vib]))
    rec = campaign(truth_with(bent(K2_X)), 2)
    cols = {k: v for k, v in rec.columns.items() if not k.startswith("sd_")}
    write_recording(tmp_path / "nosd.csv", Recording.from_columns(cols))
    code = soakcal(["diagnose", str(tmp_path / "nosd.csv"), "--against",
                    str(tmp_path / "vib.json")])
    assert code == 2
    err = capsys.readouterr().err
    assert "the twin's vibration_rectification cannot be evaluated on this recording" in err
    assert "no sd_* columns" in err
