"""Held-out residual RMS by whole plateaus (never single rows): docs/diagnosis.md §6.

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
    """Noise-weighted RMS (µg) of held-out prediction errors, fitting weighted LS on the
    other folds: ``sqrt(Σ w²·err² / Σ w²)`` (the plain RMS when every reading is as noisy).

    Why weighted (issue 22): with unequal noise (a vibrating cold plateau's readings
    scatter 10–20× more than a quiet one's) the plain RMS is the noisy plateaus' own
    scatter, and a term's real gain on the quiet plateaus drowned in the cross term of
    its small change of prediction with that scatter: terms at p ≈ 10⁻¹⁸ were rejected
    as "no held-out gain". Weighted as the fit itself is, each plateau counts by its
    information.
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
