"""The one thermal plant (calibration/thermal_plant.py) against independent references.

The references are numerical integrations of the ODE ``y' = (u − y)/τ`` by scipy's RK45
at tight tolerances, not the closed forms under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from calibration import thermal_plant as tp
from calibration.discrepancy import rig


def _integrate(u_of_t, t_eval: np.ndarray, y0: float, tau_s: float) -> np.ndarray:
    sol = solve_ivp(
        lambda t, y: (u_of_t(t) - y) / tau_s,
        (t_eval[0], t_eval[-1]),
        [y0],
        t_eval=t_eval,
        rtol=1e-11,
        atol=1e-11,
        max_step=5.0,
    )
    return sol.y[0]


def test_lag_step_is_the_exact_solution_for_a_held_input():
    t = np.linspace(0.0, 1500.0, 7)
    ref = _integrate(lambda _t: -40.0, t, 25.0, 300.0)
    got = [tp.lag_step(25.0, -40.0, float(dt), 300.0) for dt in t]
    np.testing.assert_allclose(got, ref, atol=1e-8)
    assert tp.lag_step(12.0, 3.0, 10.0, 0.0) == 3.0  # τ ≤ 0: no lag


def test_rate_limited_moves_at_most_one_step_and_lands_on_the_target():
    assert tp.rate_limited(20.0, 60.0, 2.5) == 22.5
    assert tp.rate_limited(20.0, -40.0, 2.5) == 17.5
    assert tp.rate_limited(59.0, 60.0, 2.5) == 60.0
    assert tp.rate_limited(0.1, 0.3, 1.0) == 0.3  # exactly, not 0.1 + (0.3 − 0.1)
    assert tp.rate_limited(-40.0, 60.0, math.inf) == 60.0


def test_lag_series_is_the_recurrence_of_lag_step():
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(0.0, 0.5, 400)) + 20.0
    y = [u[0]]
    for v in u[1:]:
        y.append(tp.lag_step(y[-1], float(v), 2.0, 90.0))
    np.testing.assert_allclose(tp.lag_series(u, 2.0, 90.0), y, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(tp.lag_series(u, 2.0, 0.0), u)


@pytest.mark.parametrize("tau_s", [60.0, 600.0, 2400.0])
def test_lag_behind_piecewise_linear_matches_integration(tau_s):
    # ambient → ramp down → plateau → ramp up (faster) → plateau, then constant
    bt = np.array([0.0, 600.0, 2000.0, 2300.0, 4000.0])
    bv = np.array([25.0, 5.0, 5.0, 35.0, 35.0])
    t = np.linspace(0.0, 9000.0, 301)
    y = _integrate(lambda s: float(np.interp(s, bt, bv)), t, bv[0], tau_s)
    want = y - np.interp(t, bt, bv)
    got = tp.lag_behind_piecewise_linear(bt, bv, t, tau_s)
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert np.max(np.abs(want)) > 0.5  # the lag is visible: the test can fail


def test_ramp_breakpoints_reconstruct_ramps_and_plateaus():
    ramp = 2.0  # °C/min
    # three plateaus of readings (t, step): 10 °C, 40 °C, −20 °C, each 1200 s long,
    # each reached after its ramp plus a 900 s soak
    temps = {0: 10.0, 1: 40.0, 2: -20.0}
    t_rows, s_rows = [], []
    start = 0.0
    prev = 10.0
    for s, temp in temps.items():
        first = start + abs(temp - prev) / ramp * 60.0 + 900.0
        t_rows += list(np.linspace(first, first + 1200.0, 5))
        s_rows += [s] * 5
        start, prev = first + 1200.0, temp
    t_s, steps = np.array(t_rows), np.array(s_rows)
    bt, bv = tp.ramp_breakpoints(t_s, steps, temps, ramp, ambient_c=25.0)
    # the first plateau reached from ambient, then soaked as long as the others (900 s)
    assert bv[0] == 25.0 and bv[1] == 10.0
    assert bt[1] - bt[0] == pytest.approx(15.0 / ramp * 60.0)
    assert t_s[0] - bt[1] == pytest.approx(900.0)
    # each later ramp starts at the previous plateau's last reading, at the ramp rate
    assert bt[2] == t_s[4] and bt[4] == t_s[9]
    slopes = np.diff(bv) / np.diff(bt) * 60.0
    np.testing.assert_allclose(np.abs(slopes[[0, 2, 4]]), ramp)
    np.testing.assert_allclose(slopes[[1, 3]], 0.0)


def test_rig_cascade_tends_to_the_closed_form_when_the_air_is_fast():
    """The twin's grid cascade (lag_series twice) and the closed form agree as air_tau → 0."""
    temps = {0: -20.0, 1: 20.0, 2: 60.0}
    t_s = np.concatenate(
        [np.linspace(3000.0 + 4000.0 * k, 4200.0 + 4000.0 * k, 6) for k in range(3)]
    )
    steps = np.repeat([0, 1, 2], 6)
    bt, bv = tp.ramp_breakpoints(t_s, steps, temps, 2.0, tp.AMBIENT_C)
    closed = tp.lag_behind_piecewise_linear(bt, bv, t_s, 600.0)
    grid = rig.die_minus_air_c(t_s, steps, temps, 600.0, air_tau_s=1e-6, ramp_c_per_min=2.0)
    # a held end value over each 2 s grid step leads the ramp by ~1 s: r·1 s ≈ 0.03 °C
    np.testing.assert_allclose(grid, closed, atol=0.04)
    assert np.max(np.abs(closed)) > 1.0
