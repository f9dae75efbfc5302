"""benchmarks/blind/gen2/outlier_tail_fitout.py and outlier_plateau_scale.py: the variants
of the outlier null's tail measured and not kept.

The measured variant of the outlier null's tail (docs/benchmarks.md, "The outlier null's
tail with the largest readings fitted out: measured, not kept") reads the other readings
from the fit with the largest readings given their own columns. That fit must be the fit
without those readings: the residual elsewhere is the least-squares residual of the rows
that remain, and the reading's own entries are fitted exactly.
"""

from types import SimpleNamespace

import numpy as np

from benchmarks.blind.gen2.outlier_tail_fitout import _fit_out
from calibration.discrepancy import stats


def test_a_reading_fitted_out_is_the_fit_without_it():
    rng = np.random.default_rng(5)
    n, g = 40, 3
    row = np.repeat(np.arange(n), g)
    X = rng.standard_normal((n * g, 6))
    y = rng.standard_normal(n * g)
    y[row == 7] += 25.0  # a far reading, pulling the fit with it
    U = stats.orthonormal_basis(X)
    e = y - U @ (U.T @ y)
    U2, e2 = _fit_out(SimpleNamespace(row=row), U, e, 7)
    rest = row != 7
    beta, *_ = np.linalg.lstsq(X[rest], y[rest], rcond=None)
    np.testing.assert_allclose(e2[rest], y[rest] - X[rest] @ beta, atol=1e-10)
    np.testing.assert_allclose(e2[~rest], 0.0, atol=1e-10)
    np.testing.assert_allclose(U2.T @ U2, np.eye(U2.shape[1]), atol=1e-10)
    assert not np.allclose(e[rest], e2[rest])  # the far reading had leaked into the others


def test_studentised_per_plateau_sets_each_plateaus_median_and_leaves_small_ones():
    from scipy import stats as sps

    from benchmarks.blind.gen2.outlier_plateau_scale import MIN_PLATEAU, _studentise

    rng = np.random.default_rng(7)
    steps = np.repeat([0, 1, 2], [20, 30, MIN_PLATEAU - 1])
    scale = np.repeat([1.0, 4.0, 9.0], [20, 30, MIN_PLATEAU - 1])
    t = rng.chisquare(3, (steps.size, 4)) * scale[:, None]
    live = np.ones(steps.size, bool)
    out = _studentise(t, steps, live, 3)
    for k in (0, 1):
        np.testing.assert_allclose(np.median(out[steps == k], axis=0), sps.chi2.ppf(0.5, 3))
    np.testing.assert_array_equal(out[steps == 2], t[steps == 2])
