"""The text report says when the final residual is well above the recorded noise.

The χ² excess test does not enter the verdict (sd/√n of real averages is often optimistic),
but "No mismatch: the residuals are consistent with noise" beside residuals at 2.8 × the
recorded noise is a confident wrong sentence (calibration/discrepancy/report.py,
``excess_line``).
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
    assert d.findings == [] and d.mode == "norm"
    text = text_report(d)
    assert "consistent with noise" not in text
    (line,) = [ln for ln in text.splitlines() if "Left unexplained" in ln]
    ratio = d.unexplained["chi_square"]["rms_over_noise"]
    assert ratio > 2
    assert f"{ratio:.2f} × the recorded noise" in line
    assert "repeat positions or plateaus" in line


def test_residuals_at_the_recorded_noise_are_called_noise():
    d = diagnose(_norm_recording(1.0), n_null=30, seed=1)
    text = text_report(d)
    assert "No mismatch: the residuals are consistent with noise." in text
    assert "Left unexplained" not in text
