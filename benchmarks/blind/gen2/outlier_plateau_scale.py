"""The outlier statistic studentised against its own plateau: measured, not kept.

    python -m benchmarks.blind.gen2.outlier_plateau_scale -- GEN2_RUN_ARGS

``benchmarks.blind.gen2.run`` with ``diagnose``'s outlier family changed in two places (the
benchmark's processes fork after the patch; ``calibration/`` is untouched):

* each reading's leave-one-reading-out statistic (``stats.row_stats``) is divided by its
  plateau's median statistic over χ²_g's median, in the data and in every null replicate
  alike (each replicate by its own plateau medians), plateaus of at least
  :data:`MIN_PLATEAU` readings under test; the other readings keep the recording's scale.
  Why: on about half of the outliers missed at 2× the readings' heavy tail is a spread of
  scale from plateau to plateau (docs/benchmarks.md, "The outlier null's tail with the
  largest readings fitted out"), which the per-reading Student-t null models as if each
  reading drew its own scale.
* the null's tail ν is read from the studentised statistic, against the same ratio of
  :data:`N_CAL` Gaussian replicates studentised alike (a fixed stream, not the
  diagnosis'), so the noise of a plateau's median, which the replicates carry by
  themselves, is not counted a second time as a tail: ν solves
  log-ratio(g·F(g, ν)) − log-ratio(χ²_g) = data's log-ratio − the replicates' median.

Everything is held in memory (the (N × B) statistics), which is fine on the second
generator's recordings (at most ~700 readings) and not at 1 M readings.
"""

from __future__ import annotations

import importlib
import sys
from typing import Any

import numpy as np
from scipy import stats as sps

from benchmarks.blind.gen2.outlier_tail_fitout import fitout_row_stats
from calibration.discrepancy import stats

dmod = importlib.import_module("calibration.discrepancy.diagnose")  # the module
MIN_PLATEAU = 8
# The tail read with the two largest readings fitted out by their own columns
# (outlier_tail_fitout): with them in, their leakage sets their plateau's median.
FIT_OUT = True
N_CAL = 100
_orig_row_stats = stats.row_stats
_steps: list[np.ndarray | None] = [None]


def _studentise(t: np.ndarray, steps: np.ndarray, live: np.ndarray, g: int) -> np.ndarray:
    """t (N,) or (N, B) divided per plateau by its median over χ²_g's (live readings)."""
    out = t.copy()
    c = sps.chi2.ppf(0.5, g)
    for k in np.unique(steps):
        m = (steps == k) & live
        if m.sum() >= MIN_PLATEAU:
            med = np.median(t[m], axis=0)
            out[m] = t[m] * (c / np.maximum(med, 1e-300))
    return out


def _row_q(U: Any, E: np.ndarray, row: np.ndarray, n_rows: int, skip: set[int],
           shared: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, int]:
    """(N, B) statistic of every reading on each replicate (unscaled), and the live mask."""
    g = int(np.bincount(row).max())
    idx = np.argsort(row, kind="stable").reshape(n_rows, g)
    Ug = np.asarray(U)[idx]
    if shared is None:
        M = np.eye(g)[None] - np.einsum("ngp,nhp->ngh", Ug, Ug)
    else:
        M = stats._residual_cov_blocks(np.asarray(U), Ug, np.clip(shared, -1.0, 1.0), idx)
    ok = np.array([i not in skip for i in range(n_rows)]) & (np.linalg.det(M) > 1e-6)
    Minv = stats.inverse_where(M, ok)
    Eg = np.asarray(E, float)[idx]
    return np.einsum("ngb,ngh,nhb->nb", Eg, Minv, Eg), ok, g


def row_stats(U, e, E, row, n_rows, s, s_null, skip, shared=None, reading_dof=np.inf,
              rng=None, bounded=None):
    """``stats.row_stats`` studentised per plateau (the family test's call, B > 1 only)."""
    steps = _steps[0]
    if steps is None or E.shape[1] < 2:
        return _orig_row_stats(U, e, E, row, n_rows, s, s_null, skip, shared, reading_dof,
                               rng, bounded)
    t, _, g = _orig_row_stats(U, e, np.zeros((e.size, 1)), row, n_rows, s, np.ones(1), skip,
                              shared, bounded=bounded)
    q, ok, g = _row_q(U, E, row, n_rows, skip, shared)
    if np.isfinite(reading_dof) and rng is not None:
        w = reading_dof / stats._child(rng).chisquare(reading_dof, q.shape)
        q *= w / stats.tail_scale(reading_dof)
    q /= np.asarray(s_null)[None, :] ** 2
    live = ok & (t > 0)
    t_s = np.where(live, _studentise(t, steps, live, g), t)
    q_s = np.where(live[:, None], _studentise(q, steps, live, g), 0.0)
    return t_s, q_s.max(axis=0), g


def _log_ratio(t: np.ndarray) -> float:
    """The log ratio stats.reading_tail_dof reads (its order statistics, two outliers)."""
    t = np.sort(t[np.isfinite(t)])
    n, k = t.size, stats.TAIL_OUTLIERS
    r = max(k + 2, int(np.ceil((1 - stats.TAIL_P_HI) * n)))
    q_lo, q_hi = t[int(np.ceil(stats.TAIL_P_LO * n)) - 1], t[n - r]
    return float(np.log(q_hi / q_lo)) if q_lo > 0 else np.nan


def reading_dof(pb, U, e, s, terms) -> tuple[float, float]:
    """ν of the studentised statistic's tail beyond what studentising gives Gaussian noise."""
    _steps[0] = pb.ctx.steps
    skip = {r for t in terms for r in t.rows}
    if FIT_OUT:
        t, g = fitout_row_stats(pb, U, e, s, skip)
    else:
        t, _, g = _orig_row_stats(U, e, np.zeros((pb.m, 1)), pb.row, pb.ctx.n, s,
                                  np.ones(1), skip, pb.shared_t_loading)
    top = t >= np.finfo(float).max  # the two fitted out: at the top, in no plateau's median
    n = pb.ctx.n
    if n < stats.TAIL_MIN_READINGS:
        return np.inf, np.inf
    E = stats.null_replicates(np.random.default_rng(12345), pb.m, N_CAL, pb.row,
                              pb.shared_t_loading, np.float64)
    stats.project_out_inplace(U, E)
    q, ok, g = _row_q(U, E, pb.row, n, skip, pb.shared_t_loading)
    live = ok & (t > 0)
    t_s = np.where(top, t, _studentise(t, pb.ctx.steps, live & ~top, g))[live]
    q_s = _studentise(q, pb.ctx.steps, live, g)[live]
    r_data = _log_ratio(t_s)
    r_gauss = float(np.nanmedian([_log_ratio(q_s[:, b]) for b in range(N_CAL)]))
    p_lo = stats.TAIL_P_LO
    nt = int(live.sum())
    rr = max(stats.TAIL_OUTLIERS + 2, int(np.ceil((1 - stats.TAIL_P_HI) * nt)))
    p_hi = 1 - (rr - stats.TAIL_OUTLIERS - 0.5) / (nt - stats.TAIL_OUTLIERS)
    c_lo, c_hi = sps.chi2.ppf([p_lo, p_hi], g)
    excess = r_data - r_gauss
    if not np.isfinite(excess) or excess <= 0:
        return np.inf, np.inf

    def gap(nu: float) -> float:
        lo, hi = sps.f.ppf([p_lo, p_hi], g, nu)
        return float(np.log(hi / lo) - np.log(c_hi / c_lo)) - excess

    if gap(stats.TAIL_DOF_MIN) <= 0:
        return stats.TAIL_DOF_MIN, np.inf
    if gap(stats.TAIL_DOF_MAX) >= 0:
        return np.inf, np.inf
    from scipy.optimize import brentq

    return float(brentq(gap, stats.TAIL_DOF_MIN, stats.TAIL_DOF_MAX, xtol=1e-3)), np.inf


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    from benchmarks.blind.gen2 import run

    dmod._reading_dof = reading_dof
    stats.row_stats = row_stats
    return run.main(argv[1:] if argv[:1] == ["--"] else argv)


if __name__ == "__main__":
    raise SystemExit(main())
