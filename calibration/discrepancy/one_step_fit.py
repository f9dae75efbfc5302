"""A thermal/time-family term against "plateau s differs", by fit (issue 22).

``diagnose._concentrated_on_one_step`` asks of every accepted term whether its evidence is
one plateau alone: with a free SFEM block on plateau s (12 columns), is the term still
significant at α? For the family whose columns are per-axis offsets by plateau or history
(``CatalogueEffect.named_by_fit``: session offset, hysteresis, drift, a step of the
temperature channel, …) that nested test asks more than a name needs. After the cubic in
T a per-plateau offset keeps a few contrasts per axis; freeing the plateau with most
leverage on them leaves the term's remnant beyond it, which must clear the χ² quantile at
α on its own. On gen3 at twice the detectable size (seed 1, a power cycle on a random
plateau order with 7–11 plateaus) this withheld the name as "a change confined to step s"
12 times in 52, in one case at a plateau the jump does not touch (the first, at room
temperature), where the data fitted the jump better than that plateau's change.

The question by_fit answers for rivals of the family is the one asked here: does the data
choose the term over "plateau s differs"? For each plateau s three rivals, each fitted after
the other terms: a per-axis offset of that plateau alone (the simplest change confined to
it: a warm-up, an event), the nested check's free SFEM block of it (offset and gains: a
re-seat, a change of the mount), and the term's own columns on that plateau alone (its
shape, confined: a channel that reads off on that plateau only). The term must lead the
best of them by :data:`by_fit.MARGIN` noise variances, each fit less 2 per column (AIC).
Under such a change at separation δ the lead is about N(−δ, 4δ): the name is wrong with
probability at most α (by_fit's argument), whichever plateau changed. Under the term the
lead grows as its separation δ from the rival, where the nested test needs its remnant
beyond χ²₃ at α (12.8): a name at δ = 5, 10, 15 with probability about 0.36, 0.70, 0.86
against 0.16, 0.45, 0.71.

Where the cubic leaves one contrast of the plateaus per SFEM parameter (five plateaus),
every per-plateau change lies nearly along it and the term's own shape on one plateau fits
as well: withheld there as before. The terms outside the family (orientation, geometry,
outliers) keep the nested test.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.by_fit import MARGIN
from calibration.discrepancy.effects.base import per_axis

N_RIVAL_COLUMNS = 12  # the widest rival: a free SFEM block of the plateau


def plateau_inputs(ctx: Any, step: int) -> np.ndarray:
    """(N,4): 1, a_x, a_y, a_z on plateau ``step``'s readings, 0 elsewhere — the columns of
    "plateau ``step`` differs" (offset and gains) for one axis."""
    return np.column_stack([np.ones(ctx.n), ctx.input_g]) * (ctx.steps == step)[:, None]


def sfem_block(ctx: Any, step: int) -> np.ndarray:
    """(N,3,12) raw columns: :func:`plateau_inputs` in each axis' own four (the nested
    check's "plateau differs" block, diagnose._one_step_block)."""
    u = plateau_inputs(ctx, step)
    block = np.zeros((ctx.n, 3, 12))
    for a in range(3):
        block[:, a, 4 * a:4 * a + 4] = u
    return block


def one_plateau_rivals(pb: Any, term_X: np.ndarray,
                       shape_at: Callable[[int], np.ndarray | None]
                       ) -> list[tuple[int, np.ndarray]]:
    """(plateau id, lifted columns) for each plateau: its per-axis offset, its free SFEM
    block (offset and gains: a re-seat, a change of the mount) and the term's shape on its
    readings only — the term's columns (``term_X``, lifted) where they act there, else
    ``shape_at(s)`` (the effect's columns with plateau s on, when it is profiled over the
    plateaus: "plateau 0 differs" in a channel step's shape is the complement of a step
    from plateau 1 on), else none."""
    ctx = pb.ctx
    on_step = ctx.steps[pb.row]
    out = []
    for s in ctx.step_ids:
        out.append((int(s), pb.lift(per_axis(ctx, (ctx.steps == s).astype(float)))))
        out.append((int(s), pb.lift(sfem_block(ctx, int(s)))))
        rows = (on_step == s)[:, None]
        shape = term_X if np.any(np.where(rows, term_X, 0.0)) else shape_at(int(s))
        if shape is not None:
            out.append((int(s), np.where(rows, shape, 0.0)))
    return out


def one_plateau_fits_as_well(pb: Any, terms: list, term: Any, one_sided: bool,
                             design: Callable[..., tuple[np.ndarray, np.ndarray]],
                             shape_at: Callable[[int], np.ndarray | None] = lambda s: None
                             ) -> tuple[bool, int | None]:
    """(decided, step): ``decided`` False when the recording is too long for the design (the
    caller keeps its nested test); else ``step`` is the plateau whose change alone fits the
    term's structure as well (the term leads it by less than by_fit.MARGIN), or None when
    the term leads every plateau's. ``terms``: the accepted terms before ``term``;
    ``shape_at(s)``: the effect's lifted columns with plateau s on, or None
    (:func:`one_plateau_rivals`)."""
    ctx = pb.ctx
    if len(ctx.step_ids) < 3:
        return True, None
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in terms) + max(N_RIVAL_COLUMNS,
                                                                 term.X.shape[1])
    if 8 * pb.m * p > stats.TALL_BYTES or pb.m <= p + 10:
        return False, None
    Xw, yw = design(pb, terms)
    U = stats.orthonormal_basis(Xw)
    del Xw
    e = yw - U @ (U.T @ yw)
    q_term, k_term = stats.explained_ss(U, pb.whiten(term.X), e, one_sided)
    fits = [(s, *stats.explained_ss(U, pb.whiten(X), e))
            for s, X in one_plateau_rivals(pb, term.X, shape_at)]
    fits = [(s, q, k) for s, q, k in fits if k > 0]
    if k_term == 0 or not fits:
        return True, None
    k_max = max([k_term] + [k for _, _, k in fits])
    q_max = max([q_term] + [q for _, q, _ in fits])
    s2 = max((float(e @ e) - q_max) / max(e.size - U.shape[1] - k_max, 1), 1e-300)
    leads = {}
    for s, q, k in fits:
        lead = (q_term / s2 - 2.0 * k_term) - (q / s2 - 2.0 * k)
        leads[s] = min(lead, leads.get(s, np.inf))
    step = min(leads, key=leads.get)
    return True, (step if leads[step] < MARGIN else None)
