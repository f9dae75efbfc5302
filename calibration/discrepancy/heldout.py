"""Held-out residual RMS, noise-weighted, by whole plateaus (not single rows): docs §6.

Folds are the interior temperature steps (leave-one-step-out; the end steps
are never held out because a cubic does not extrapolate and that would test
the polynomial, not the effect). A recording with one plateau is split into
contiguous time intervals (leave-one-interval-out) and says so.
"""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.context import DesignContext

N_INTERVALS = 5


def folds(ctx: DesignContext) -> tuple[list[np.ndarray], str]:
    """Row masks of the held-out folds and a description of the scheme."""
    ids = ctx.step_ids
    if len(ids) >= 4:
        return [ctx.steps == s for s in ids[1:-1]], "leave-one-step-out (interior steps)"
    order = np.argsort(ctx.t_s, kind="stable")
    blocks = np.array_split(order, N_INTERVALS)
    out = []
    for b in blocks:
        m = np.zeros(ctx.n, bool)
        m[b] = True
        out.append(m)
    return out, f"leave-one-interval-out ({N_INTERVALS} contiguous time intervals)"


def heldout_rms_ug(y: np.ndarray, X: np.ndarray, w: np.ndarray, row: np.ndarray,
                   fold_masks: list[np.ndarray], exclude_rows: np.ndarray) -> float:
    """Noise-weighted RMS (µg) of held-out prediction errors, weighted LS on the other folds.

    ``sqrt(Σ w²·err² / Σ w²)``: each error counts by its reading's inverse noise variance,
    as in the fit (equal noise: the plain RMS). Why (issue 22): with one plateau's capture
    means 10–20 × noisier than the rest (a vibrating bench), the plain RMS is that
    plateau's noise, and whether a term "improved" it was a coin toss: a nonlinearity at
    p = 1e-11 was rejected by a 0.04 µg rise in a 103 µg figure.
    """
    sq, cnt = 0.0, 0.0
    # Columns scaled to unit norm: effect columns can be 10⁷ smaller than the base's
    # (a vibration term is ∝ sd² ≈ 1e-7 g²), and pinv's relative cut-off would drop them.
    scale = column_scale(X * w[:, None])
    X = X / scale
    Xw, yw = X * w[:, None], y * w
    G, h = Xw.T @ Xw, Xw.T @ yw
    for m in fold_masks:
        test = m[row] & ~exclude_rows[row]
        hold = m[row]
        if not test.any() or hold.all():
            continue
        # Normal equations with the fold removed: small (p×p), far faster than lstsq per fold.
        Gt = G - Xw[hold].T @ Xw[hold]
        ht = h - Xw[hold].T @ yw[hold]
        beta = np.linalg.pinv(Gt, rcond=1e-12, hermitian=True) @ ht
        err = (y[test] - X[test] @ beta) * w[test]
        sq += float(err @ err)
        cnt += float(w[test] @ w[test])
    return float(np.sqrt(sq / cnt) * 1e6) if cnt > 0 else 0.0


def column_scale(Xw: np.ndarray) -> np.ndarray:
    """Norm of each (whitened) column, 1 for empty columns: divide by it before solving."""
    nrm = np.sqrt(np.sum(Xw**2, axis=0))
    return np.where(nrm > 0, nrm, 1.0)
