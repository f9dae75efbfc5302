"""The norm-mode base model behind diagnose is the joint SFEM fit (calibration.thermal_joint)."""

from __future__ import annotations

import json

import numpy as np

from calibration import schedules
from calibration.discrepancy import diagnose
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth


def test_six_axis_directions_per_step_get_a_base_fit_not_a_diverged_one() -> None:
    # Six axis directions visited twice per step, norm mode: the α are not determined, and
    # an undamped Gauss–Newton on the 9×3 coefficients diverged (|f| off by 0.7 g), after
    # which diagnose called the recording "consistent" with a noise of 0.83 g.
    truth = SensorTruth.adxl355_typical(11)
    truth.temp_offset_c = 0.0  # the sensor channel reads the die
    rec = simulate_campaign(truth, (-20.0, 20.0, 60.0), seed=1011,
                            schedule=np.vstack([schedules.six_position()] * 2))
    norm = Recording.from_columns({k: v for k, v in rec.columns.items()
                                   if not k.startswith("ref_")})
    pb = build_problem(norm)
    assert float(np.sqrt(np.mean(pb.y**2))) * 1e6 < 50.0  # |f| − 1 at the base fit, µg
    doc = json.loads(diagnose(norm, seed=1, n_null=20).to_json())
    assert doc["verdict"] == "cannot judge"  # 36 readings, 27 coefficients: 9 dof < 10
    assert "leave 9 residual degree(s) of freedom" in doc["reason"]
