"""A named finding is stated in the model that is kept, not the one of its stage.

A finding's coefficients were fitted when its term was added. A term withdrawn after that
(a turn of the table that shared the bend's columns, say) leaves those numbers stale: on
the second generator an ADC band error then read "K3 = −335,400 µg/g³ ± 49", two terms
cancelling each other, while the kept model's K3 is a few µg/g³.
"""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.diagnose import Term, _finding, _restated, _term_coefficients
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.problem import build_problem
from simulators import effects as E  # noqa: N812 (as the other discrepancy tests)
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 20)]


def test_a_named_finding_is_restated_after_a_term_that_shared_its_columns_is_withdrawn():
    bend = E.ScaleNonlinearity(k2_per_g=np.array([0.0, 0.0, 40e-6]),
                               k3_per_g2=np.zeros(3))
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=3, effects=[bend]),
                            setpoints_c=ONE_WAY, seed=13)
    pb = build_problem(rec)
    eff = BY_ID["scale_nonlinearity"]
    X = eff.regressors(pb.ctx, float("nan")).reshape(pb.m, -1)
    term = Term("scale_nonlinearity", float("nan"), X)
    # a rival that shares the bend's columns up to a small difference: fitted together the
    # two cancel, each with a coefficient far beyond the structure
    rng = np.random.default_rng(0)
    rival = Term("cross_coupling", float("nan"), X + 1e-3 * rng.standard_normal(X.shape) * X.std())
    stale = _finding(pb, eff, None, term, [term, rival], {}, 1e-9, 1.0, 1.0, 1.0, 1.0)
    (kept,) = _restated(pb, [term], [stale])
    coef, _ = _term_coefficients(pb, [term], term)
    k2_z = coef[2] * 1e6
    assert abs(kept.parameters["k2_z_ug_per_g2"] - k2_z) <= 1e-3 * abs(k2_z)
    assert 20.0 < kept.parameters["k2_z_ug_per_g2"] < 60.0  # the simulated 40 µg/g²
    assert abs(stale.parameters["k2_z_ug_per_g2"] - k2_z) > 5.0
    assert f"{kept.parameters['k2_z_ug_per_g2']:.0f}" in kept.explanation.replace(" ", "")
    # a finding whose term is not in the model, or not named as its term, is left as it is
    assert _restated(pb, [rival], [stale])[0] is stale
