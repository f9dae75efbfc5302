"""benchmarks/blind/gen2/outlier_tail_fitout.py: a reading fitted out by its own columns.

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
