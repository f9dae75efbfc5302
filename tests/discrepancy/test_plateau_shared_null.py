"""A null that keeps its level when the readings of a plateau share noise (issue 22).

A random offset per plateau and axis (a die-temperature error of the plateau through
∂output/∂T, a chamber state) is not absorbed by a base model smooth in T. Sign flips per
reading remove it from the replicates, so a column constant within plateaus (hysteresis, a
one-plateau change) is tested against a null without it; drawn back in at the variance the
residual shows (stats.shared_variance, stats.add_shared), the test is at its level.
diagnose does not use that draw (diagnose.PLATEAU_NULL, off): an effect confined to plateaus
raises its own variance estimate and lost its power (docs/diagnosis.md §2).
"""

import numpy as np
import pytest

from calibration.discrepancy import stats
from tests.discrepancy.plateau_layout import plateau_layout

K, PER = 8, 18  # plateaus, readings per plateau


def _layout():
    n, step, row, axis, U = plateau_layout(K, PER)
    groups = stats.SharedGroups([np.ones(3 * n)], [step[row] * 3 + axis], ["plateau x axis"])
    return n, step, row, axis, U, groups


def _p(lp, lpn):
    return (1 + np.sum(lpn <= lp)) / (lpn.size + 1)


def _hysteresis(step, row, axis):
    """±1 by the direction of the last excursion (up on the first half, down after)."""
    d = np.where(step < K // 2, 1.0, -1.0)[row]
    return np.column_stack([np.where(axis == a, d, 0.0) for a in range(3)])


def test_plateau_offsets_break_sign_flips_and_the_shared_draw_restores_the_level():
    rng = np.random.default_rng(5)
    n, step, row, axis, U, groups = _layout()
    X = _hysteresis(step, row, axis)
    R, B = 150, 200
    p_wild, p_shared = [], []
    for _ in range(R):
        y = rng.standard_normal(3 * n) + 0.8 * rng.standard_normal(3 * K)[step[row] * 3 + axis]
        e = stats.project_out(U, y)
        lp = stats.linear_stats(U, X, e, np.zeros((3 * n, 1)))[0]
        theta, s2 = stats.shared_variance(e, U, groups)
        W = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)))
        S = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)),
                                  shared=(groups, theta, s2))
        p_wild.append(_p(lp, stats.linear_stats(U, X, e, W)[1]))
        p_shared.append(_p(lp, stats.linear_stats(U, X, e, S)[1]))
    p_wild, p_shared = np.array(p_wild), np.array(p_shared)
    assert np.mean(p_wild <= 0.05) > 0.25  # far above its level without the shared part
    assert np.mean(p_shared <= 0.05) <= 0.09  # binomial sd at 150 draws: 1.8 %
    assert np.mean(p_shared <= 0.20) == pytest.approx(0.20, abs=0.08)


def test_the_variance_of_plateau_offsets_is_estimated_and_none_where_there_is_none():
    rng = np.random.default_rng(6)
    n, step, row, axis, U, groups = _layout()
    th0, th1 = [], []
    for _ in range(40):
        z = rng.standard_normal(3 * n)
        b = 0.5 * rng.standard_normal(3 * K)[step[row] * 3 + axis]
        th0.append(stats.shared_variance(stats.project_out(U, z), U, groups)[0][0])
        th1.append(stats.shared_variance(stats.project_out(U, z + b), U, groups)[0][0])
    assert np.median(th0) < 0.01  # white noise: θ at (or next to) zero
    assert np.median(th1) == pytest.approx(0.25, rel=0.4)
