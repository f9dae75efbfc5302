"""``temperature_rate`` is named only when its gains are not a lag's (issue 22, effects.md).

A temperature channel lagging the die by τ reads T − τ·dT/dt, so the base model misses
∂output/∂T·τ·dT/dt on each axis: a rate term with its three gains locked to the model's
own slope (one τ). ``temperature_rate.lag_check`` tests the free per-axis gains after that
locked column (F at α). Both directions are checked: a lagging channel adds nothing to
the locked fit (and its τ is recovered); a rate with equal gains on all axes — not the
per-axis pattern of ∂output/∂T — is told from a lag and still named.
"""

from __future__ import annotations

import numpy as np

from benchmarks.blind.outside import _lag_channel
from calibration.discrepancy import diagnose
from calibration.discrepancy.effects.temperature_rate import lag_check
from calibration.discrepancy.problem import build_problem
from calibration.discrepancy.stats import orthonormal_basis
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
UP_DOWN = [float(t) for t in list(range(-40, 61, 20)) + list(range(50, -41, -20))]
ALPHA = 0.005
TAU_S = 776.0
EQUAL_GAINS_G_PER_C_PER_S = 3e-3  # 3000 µg per °C/s on each axis


def _check(rec):
    pb = build_problem(rec)
    U = orthonormal_basis(pb.X0 * pb.w[:, None])
    yw = pb.y * pb.w
    return lag_check(pb, U, yw - U @ (U.T @ yw))


def _lagging():
    truth = SensorTruth.adxl355_typical(seed=31016)
    return _lag_channel(simulate_campaign(truth, ONE_WAY, seed=41016, soak_min=30.0), TAU_S)


def _rate():
    rate = fx.TemperatureRate(np.full(3, EQUAL_GAINS_G_PER_C_PER_S))
    truth = SensorTruth.adxl355_typical(seed=31016, effects=[rate])
    return simulate_campaign(truth, UP_DOWN, seed=41016, soak_min=30.0)


def test_a_lagging_channel_is_the_locked_fit_with_its_tau():
    c = _check(_lagging())
    assert c.dof >= 2 and c.log_p_free > np.log(ALPHA)
    assert 0.5 * TAU_S < c.tau_s < 1.5 * TAU_S


def test_equal_rate_gains_are_not_a_lag():
    c = _check(_rate())
    assert c.dof >= 2 and c.log_p_free < np.log(ALPHA)


def test_a_rate_with_gains_not_locked_to_the_slope_is_still_named():
    d = diagnose(_rate(), n_null=200, seed=16)
    assert [f.effect for f in d.findings] == ["temperature_rate"], d.notes
