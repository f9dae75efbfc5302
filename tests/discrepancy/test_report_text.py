"""The text report: a final residual well above the recorded noise is said, not called
noise; a two-sided confusion says which effects from which.

"No mismatch: the residuals are consistent with noise" beside residuals at 2.8 × the
recorded noise is a confident wrong sentence: where no test located or named the excess,
the χ² excess test's own `unexplained` finding makes the verdict a mismatch and says both
possible causes (calibration/discrepancy/diagnose.py ``_excess_finding``).
"""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.diagnose import diagnose
from calibration.discrepancy.report import text_report
from calibration.recording import Recording
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth


def _norm_recording(sd_scale: float) -> Recording:
    """A plain sensor on a one-way staircase, no references (norm mode: σ is sd/√n as
    recorded), its recorded sd multiplied by ``sd_scale``."""
    truth = SensorTruth.adxl355_typical(seed=1, effects=[])
    rec = simulate_campaign(truth, setpoints_c=[float(t) for t in range(-40, 61, 20)],
                            seed=11, position_order="random", position_order_seed=3)
    cols = {k: v for k, v in rec.columns.items() if not k.startswith("ref_")}
    for k in ("sd_x", "sd_y", "sd_z"):
        cols[k] = np.asarray(cols[k], float) * sd_scale
    return Recording.from_columns(cols)


def test_residuals_above_an_understated_noise_are_not_called_noise():
    d = diagnose(_norm_recording(1 / 3), n_null=30, seed=1)
    assert d.mode == "norm" and d.mismatch
    (f,) = d.findings
    assert f.effect == "unexplained" and f.where["spread"]
    text = text_report(d)
    assert "consistent with noise" not in text
    ratio = d.unexplained["chi_square"]["rms_over_noise"]
    assert ratio > 2
    (line,) = [ln for ln in text.splitlines() if "× the recorded noise" in ln]
    assert f"{ratio:.2f} × the recorded noise" in line
    assert "understates the scatter" in line and "Repeat positions or plateaus" in line


def test_residuals_at_the_recorded_noise_are_called_noise():
    d = diagnose(_norm_recording(1.0), n_null=30, seed=1)
    text = text_report(d)
    assert "No mismatch: the residuals are consistent with noise." in text
    assert "Left unexplained" not in text


def test_a_two_sided_confusion_says_which_from_which():
    """One plateau read once per position: time terms are confused with orientation terms,
    not scale_nonlinearity with cross_coupling (told apart by their own shapes)."""
    from calibration.discrepancy.report import protocol_lines

    pr = {"temperature": "none", "n_plateaus": 1, "temperature_source": "",
          "position_order": "one plateau", "order_from": "t_s", "references": False,
          "sessions": None, "oblique_positions": True, "separable": ["outlier"],
          "not_separable": [{"effects": ["self_heating", "bias_drift", "scale_nonlinearity",
                                         "cross_coupling"], "why": "one plateau",
                             "finding_withheld": False,
                             "versus": ["scale_nonlinearity", "cross_coupling"]},
                            {"effects": ["thermal_lag", "bias_drift"], "why": "no temperature",
                             "finding_withheld": False}]}
    lines = protocol_lines(pr)
    assert ("  cannot separate self_heating / bias_drift from scale_nonlinearity / "
            "cross_coupling: one plateau") in lines
    assert "  cannot separate thermal_lag / bias_drift: no temperature" in lines


def test_a_tail_only_at_its_point_estimate_is_not_called_heavier(monkeypatch):
    """The outlier null takes the readings' tail at its point estimate; the notes call the
    readings heavier-tailed than Gaussian only where the tail is resolved (stats.TAIL_Z)."""
    from calibration.discrepancy import stats

    rec = _norm_recording(1.0)

    def point_only(z, z_se=None):  # type: ignore[no-untyped-def]
        return 40.0 if z_se == stats.NULL_TAIL_Z else np.inf

    monkeypatch.setattr(stats, "entry_tail_dof", point_only)
    notes = " ".join(diagnose(rec, n_null=30, seed=1).notes)
    assert "heavier-tailed" not in notes
    assert "Student-t tail at its point estimate" in notes and "nu = 40.0" in notes
    assert "not told from a Gaussian" in notes

    monkeypatch.setattr(stats, "entry_tail_dof", lambda z, z_se=None: 12.0)
    notes = " ".join(diagnose(rec, n_null=30, seed=1).notes)
    assert "heavier-tailed than Gaussian (Student-t, nu = 12.0" in notes
