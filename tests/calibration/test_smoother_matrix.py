"""The dithered rebuild's local-quadratic smoother, solved by blocks of rows, is the
row-by-row smoother to rounding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from calibration import temperature_dither
from calibration.temperature_dither import smoother_matrix


def smoother_matrix_rowwise(t: np.ndarray, window_s: float) -> sparse.csr_matrix:
    """The smoother one row at a time, one 3 × 3 solve per row: the reference the blocked
    :func:`smoother_matrix` is checked against."""
    n = t.size
    lo = np.searchsorted(t, t - window_s / 2, side="left")
    hi = np.searchsorted(t, t + window_s / 2, side="right")
    rows, cols, vals = [], [], []
    for i in range(n):
        a, b = int(lo[i]), int(hi[i])
        row = None
        if b - a >= 4:
            u = (t[a:b] - t[i]) / (window_s / 2)
            w = (1.0 - np.abs(u) ** 3) ** 3
            X = np.column_stack([np.ones(b - a), u, u * u])
            A = X.T @ (w[:, None] * X)
            if np.linalg.cond(A) < 1e10:
                row = (X @ np.linalg.solve(A, np.array([1.0, 0.0, 0.0]))) * w
        if row is None:
            a, b, row = i, i + 1, np.ones(1)
        rows.append(np.full(b - a, i))
        cols.append(np.arange(a, b))
        vals.append(row)
    return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                     np.concatenate(cols))), shape=(n, n))


def _times() -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [
        np.arange(400, dtype=float),  # 1-s captures
        np.sort(rng.uniform(0.0, 2000.0, 700)),  # irregular
        np.r_[np.arange(100.0), 500.0 + np.arange(60.0) * 5.0],  # a gap: rows left alone
        np.arange(3, dtype=float),  # fewer rows than a quadratic needs
    ]


@pytest.mark.parametrize("window_s", [4.0, 20.0, 160.0])
def test_the_blocked_smoother_is_the_row_by_row_one(window_s, monkeypatch) -> None:
    monkeypatch.setattr(temperature_dither, "SMOOTHER_BLOCK_CELLS", 3000)  # several blocks
    for t in _times():
        blocked, rowwise = smoother_matrix(t, window_s), smoother_matrix_rowwise(t, window_s)
        assert blocked.shape == rowwise.shape
        np.testing.assert_array_equal(blocked.indptr, rowwise.indptr)  # the same windows
        np.testing.assert_array_equal(blocked.indices, rowwise.indices)
        np.testing.assert_allclose(blocked.toarray(), rowwise.toarray(), rtol=0, atol=1e-12)
        # a local quadratic reproduces a quadratic wherever it fits
        q = 0.3 + 0.01 * t - 2e-5 * t**2
        fitted = np.diff(blocked.indptr) > 1  # rows with a window of their own
        np.testing.assert_allclose((blocked @ q)[fitted], q[fitted], atol=1e-9)
