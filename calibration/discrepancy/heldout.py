"""Held-out residual RMS by whole plateaus or visits (never single rows): docs/diagnosis.md §6.

Folds are the interior temperature steps (leave-one-step-out; the end steps
are never held out because a cubic does not extrapolate and that would test
the polynomial, not the effect), those whose other plateaus over-determine the base's
temperature polynomial. When none does, interleaved visit groups of every plateau
(leave-one-visit-group-out). A recording with fewer than four plateaus is split into
contiguous time intervals (leave-one-interval-out) and says so.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.discrepancy.context import DesignContext

N_INTERVALS = 5


def folds(ctx: DesignContext, degree: int = 3) -> tuple[list[np.ndarray], str]:
    """Row masks of the held-out folds and a description of the scheme (:func:`plateau_folds`
    on the design's plateaus)."""
    return plateau_folds(ctx.steps, ctx.step_temp_c, ctx.t_s, ctx.positions, degree)


def plateau_folds(steps: np.ndarray, step_temp_c: dict[int, float], t_s: np.ndarray,
                  positions: np.ndarray, degree: int = 3) -> tuple[list[np.ndarray], str]:
    """Row masks of the held-out folds and a description of the scheme: the one fold rule of
    ``diagnose`` and ``diagnose --against``.

    ``steps``/``positions``: per-reading step and position indices; ``step_temp_c``: each
    step's temperature; ``degree``: the base model's polynomial degree in temperature. An
    interior step is held out only when the other plateaus hold more temperatures than that
    polynomial has coefficients; when none is, every plateau's readings are split into
    interleaved visit groups (:func:`visit_group_folds`).
    """
    ids = sorted(step_temp_c)
    if len(ids) >= 4:
        kept = [s for s in ids[1:-1] if training_levels(step_temp_c, s) > degree + 1]
        if kept:
            return [steps == s for s in kept], "leave-one-step-out (interior steps)"
        return visit_group_folds(steps, ids, t_s, positions), (
            f"leave-one-visit-group-out ({N_INTERVALS} interleaved groups of every plateau's "
            "visits: holding out a whole plateau would leave the base's temperature "
            "polynomial fitted exactly through the others)")
    order = np.argsort(t_s, kind="stable")
    blocks = np.array_split(order, N_INTERVALS)
    out = []
    for b in blocks:
        m = np.zeros(t_s.size, bool)
        m[b] = True
        out.append(m)
    return out, f"leave-one-interval-out ({N_INTERVALS} contiguous time intervals)"


def training_levels(step_temp_c: dict[int, float], held_step: int) -> int:
    """Distinct plateau temperatures (0.1 °C, as ``problem._powers`` counts them) left when
    step ``held_step`` is held out."""
    return len({round(float(t), 1) for s, t in step_temp_c.items() if s != held_step})


def visit_group_folds(steps: np.ndarray, step_ids: list[int], t_s: np.ndarray,
                      positions: np.ndarray) -> list[np.ndarray]:
    """Folds of interleaved visits: the k-th visit of plateau j (in time order; a visit is
    a run of readings at one position) goes to group (k + j) mod ``N_INTERVALS``.

    Why (issue 22): with five plateaus and a cubic in temperature, a held-out interior
    plateau is predicted by a cubic fitted exactly through the four others. Its error is
    then the cubic's interpolation error at that temperature (37 µg against a 5 µg
    cross-coupling signature on the second generator's case 0005), the same with and without
    the term, and a term's change of the four fitted plateaus moves it up or down at random:
    the comparison tests the polynomial, not the term, as holding out an end step would
    (never done, above). Held-out visits of every plateau are predicted by a model that saw
    every temperature, so the comparison asks whether the term predicts readings it was
    not fitted to. The shift by the plateau's index puts a position visited at the same
    slot of every plateau in a different group on each, so a term with one parameter per
    pose has seen each held-out pose on the other plateaus.
    """
    groups = np.zeros(t_s.size, int)
    for j, s in enumerate(step_ids):
        idx = np.flatnonzero(steps == s)
        idx = idx[np.argsort(t_s[idx], kind="stable")]
        visit = np.concatenate([[0], np.cumsum(np.diff(positions[idx]) != 0)])
        groups[idx] = (visit + j) % N_INTERVALS
    return [groups == g for g in range(N_INTERVALS)]


def heldout_rms_ug(y: np.ndarray, X: np.ndarray, w: np.ndarray, row: np.ndarray,
                   fold_masks: list[np.ndarray], exclude_rows: np.ndarray,
                   shrunk: np.ndarray | None = None, in_noise_units: bool = False) -> float:
    """Noise-weighted RMS (µg) of held-out prediction errors, fitting weighted LS on the
    other folds: ``sqrt(Σ w²·err² / Σ w²)`` (the plain RMS when every reading is as noisy).

    Why weighted (issue 22): with unequal noise (a vibrating cold plateau's readings
    scatter 10–20× more than a quiet one's) the plain RMS is the noisy plateaus' own
    scatter, and a term's real gain on the quiet plateaus drowned in the cross term of
    its small change of prediction with that scatter: terms at p ≈ 10⁻¹⁸ were rejected
    as "no held-out gain". Weighted as the fit itself is, each plateau counts by its
    information.

    ``shrunk`` (p,) bool: columns of a term with one free parameter per place (a turn of
    each table pose) fitted by ridge with an empirical-Bayes prior (:func:`_shrunk_fit`),
    on each fold's training rows only; None: plain least squares for all.
    ``in_noise_units``: ``sqrt(Σ w²·err² / n)``, an RMS in units of the noise (×10⁶).
    """
    sq, cnt = 0.0, 0.0
    yy = float((y * w) @ (y * w))
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
        beta = _fold_fit(Gt, ht, yy - float(yw[hold] @ yw[hold]), int((~hold).sum()), shrunk)
        err = (y[test] - X[test] @ beta) * w[test]
        sq += float(err @ err)
        cnt += float(test.sum()) if in_noise_units else float(w[test] @ w[test])
    return float(np.sqrt(sq / cnt) * 1e6) if cnt > 0 else 0.0


def heldout_rms_ug_by_blocks(design: Any, y: np.ndarray, row: np.ndarray,
                             fold_masks: list[np.ndarray], exclude_rows: np.ndarray,
                             shrunk: np.ndarray | None = None,
                             in_noise_units: bool = False) -> float:
    """:func:`heldout_rms_ug` with the whitened design given by row blocks
    (``basis.WhitenedDesign``: ``rows``, ``m``, ``p``, ``w``), never whole.

    Why (issue 22, memory): the whole-array form holds the design, its whitened and scaled
    copies (four (m × p) arrays: 4.6 GB at 1 M readings). The same normal equations: G, Xᵀy
    and each fold's share of them summed over row blocks, the column scale from diag(G), the
    held-out errors in a second pass.
    """
    from calibration.discrepancy import stats

    m, p, w = design.m, design.p, design.w
    yw = y * w
    holds = [f[row] for f in fold_masks]
    tests = [hold & ~exclude_rows[row] for hold in holds]
    G, h = np.zeros((p, p)), np.zeros(p)
    Gf, hf, yyf = np.zeros((len(holds), p, p)), np.zeros((len(holds), p)), np.zeros(len(holds))
    for sl in stats.row_blocks(m, p):
        B, yb = design.rows(sl), yw[sl]
        G += B.T @ B
        h += B.T @ yb
        for f, hold in enumerate(holds):
            sel = hold[sl]
            if sel.any():
                Gf[f] += B[sel].T @ B[sel]
                hf[f] += B[sel].T @ yb[sel]
                yyf[f] += float(yb[sel] @ yb[sel])
    scale = np.sqrt(np.diag(G))
    scale = np.where(scale > 0, scale, 1.0)
    outer = np.outer(scale, scale)
    yy = float(yw @ yw)
    betas: dict[int, np.ndarray] = {}
    for f, (hold, test) in enumerate(zip(holds, tests, strict=True)):
        if not test.any() or hold.all():
            continue
        beta = _fold_fit((G - Gf[f]) / outer, (h - hf[f]) / scale, yy - yyf[f],
                         int((~hold).sum()), shrunk)
        betas[f] = beta / scale  # on the unscaled whitened columns
    sq, cnt = 0.0, 0.0
    for sl in stats.row_blocks(m, p):
        B, yb = design.rows(sl), yw[sl]
        for f, beta in betas.items():
            sel = tests[f][sl]
            if sel.any():
                err = yb[sel] - B[sel] @ beta
                sq += float(err @ err)
    for f in betas:
        cnt += float(tests[f].sum()) if in_noise_units else float(w[tests[f]] @ w[tests[f]])
    return float(np.sqrt(sq / cnt) * 1e6) if cnt > 0 else 0.0


def _fold_fit(G: np.ndarray, h: np.ndarray, yy: float, n: int,
              shrunk: np.ndarray | None) -> np.ndarray:
    """A fold's coefficients from its training normal equations (scaled columns): least
    squares, or :func:`_shrunk_fit` when columns are shrunk."""
    if shrunk is not None and shrunk.any():
        return _shrunk_fit(G, h, yy, n, shrunk)
    return np.linalg.pinv(G, rcond=1e-12, hermitian=True) @ h


def _shrunk_fit(G: np.ndarray, h: np.ndarray, yy: float, n: int, b: np.ndarray) -> np.ndarray:
    """Ridge fit from the normal equations, the columns ``b`` shrunk towards 0.

    Why (issue 22): a term with a free parameter per place (2 per table pose: 48–72
    columns) fitted freely on the training plateaus adds each parameter's noise to the
    prediction, and a turn twice its detectable size then never "improves" the held-out
    error although its test is far beyond noise. Its parameters are modelled as drawn with
    one unknown variance τ² (empirical Bayes: ``E[q] = k·s² + τ²·tr S``, q the block's
    explained sum of squares after the other columns, S its Schur complement), estimated
    from the training rows alone; penalty s²/τ², none on the other columns. No evidence
    above noise (q ≤ k·s²) gives the block no weight at all.
    """
    ginv = np.linalg.pinv(G, rcond=1e-12, hermitian=True)
    beta = ginv @ h
    p_eff = int(round(float(np.trace(ginv @ G))))
    s2 = max((yy - float(h @ beta)) / max(n - p_eff, 1), 1e-300)
    a = ~b
    Gaa_inv = np.linalg.pinv(G[np.ix_(a, a)], rcond=1e-12, hermitian=True)
    S = G[np.ix_(b, b)] - G[np.ix_(b, a)] @ Gaa_inv @ G[np.ix_(a, b)]
    r = h[b] - G[np.ix_(b, a)] @ Gaa_inv @ h[a]
    S_inv = np.linalg.pinv(S, rcond=1e-12, hermitian=True)
    k = int(round(float(np.trace(S_inv @ S))))
    q = float(r @ S_inv @ r)
    tr = float(np.trace(S))
    if q <= k * s2 or tr <= 0:
        out = np.zeros_like(h)
        out[a] = Gaa_inv @ h[a]
        return out
    pen = np.zeros(h.size)
    pen[b] = s2 / ((q - k * s2) / tr)
    return np.linalg.pinv(G + np.diag(pen), rcond=1e-12, hermitian=True) @ h


def column_scale(Xw: np.ndarray) -> np.ndarray:
    """Norm of each (whitened) column, 1 for empty columns: divide by it before solving."""
    nrm = np.sqrt(np.sum(Xw**2, axis=0))
    return np.where(nrm > 0, nrm, 1.0)
