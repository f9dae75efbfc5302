"""An input-only name against a settling at each slot of the visiting order (issue 22).

``cross_coupling`` and ``scale_nonlinearity`` are functions of the specific force alone:
their offset at a position is the same on every plateau. A settling after each move (the
die or the mount relaxing, a fixture that creeps back after the table turns) is a function
of the move and of the time since the plateau began. When every plateau visits the
positions in the same order (``protocol_order.time_and_position_confounded``), the k-th
visit of each plateau is always the same position, reached by the same move at the same
time: a free per-axis offset at each slot of the order
(``protocol_order.slot_offset_columns``) then spans *every* function of the position, the
input-only terms' columns included, and no amount of data at that protocol tells them
apart. ``turntable_geometry`` (a turn of each pose) is withheld on the same ground, at the
protocol level (its ``identifiable``).

Measured on the second generator (docs/benchmarks.md, "Input-only names on a repeated
visiting order"): on every repeated-order case the oracle's λ of the true nonlinearity's
own columns after the base and the slot columns is 0 (to rounding), against 56–107 after
the base alone at 2×; on varied orders the slots take 11–61 % of it (power ≥ 0.75 at 2×).

The rule, one F test (as ``_turned_or_bent``'s against a turn of the reference): the named
term's columns after the model's other terms and the slot columns, at α. When nothing of
the term is left beyond the slots (the order repeats), or what is left is not significant
(the order varies too little between plateaus), the name is withheld: the finding becomes
``not_identifiable`` between the name and the settling, with the reason and the experiment
that separates them (a different order on some plateaus). The term stays in the model
(either removes the structure). One plateau: a settling "the same on every plateau" is
then any function of the visit, not tested here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.structure import extend
from calibration.discrepancy.protocol_order import (
    slot_offset_columns,
    time_and_position_confounded,
    visit_slots,
)
from calibration.discrepancy.temperature_jump import withheld

SLOT_SETTLING = ("a settling after each move, the same at each slot of the visiting order "
                 "(the die or the mount settling after the table turns; outside the "
                 "catalogue)")
EXPERIMENT = ("visit the positions in a different order on some plateaus (a seeded or "
              "balanced order per plateau, position_order random or balanced): a function "
              "of the specific force follows the position, a settling the slot")
MIN_STEPS = 2  # one plateau: "the same on every plateau" constrains nothing
# A direction of the term's columns counts as left beyond the slots above this share of
# their scale (singular values): below, it is rounding (the slots span it).
LEFT_REL_TOL = 1e-6


def part_beyond(U: np.ndarray, e: np.ndarray, Xw: np.ndarray) -> tuple[float, int]:
    """log p of the F test of the whitened columns ``Xw`` after the basis ``U`` (residual
    ``e``), and their rank there (0: ``U`` spans them; log p is then 0).

    Why not ``stats.linear_stats``: its rank cut is relative to the *projected* columns, so
    columns spanned up to rounding keep a few rounding directions; here the cut is relative
    to the columns before the projection."""
    Xo = stats.project_out(U, Xw)
    V, s, _ = np.linalg.svd(Xo, full_matrices=False)
    top = float(np.linalg.svd(Xw, compute_uv=False)[0]) if Xw.size else 0.0
    B = V[:, s > LEFT_REL_TOL * max(top, 1e-300)]
    k = B.shape[1]
    if k == 0:
        return 0.0, 0
    dof = max(e.size - U.shape[1] - k, 1)
    q = float(np.sum((B.T @ e) ** 2))
    f = q / k / max((float(e @ e) - q) / dof, 1e-300)
    return float(stats.f_logsf(f, k, dof)), k


def slot_settling_alike(pb: Any, terms: list, f: Any, alpha: float,
                        not_ident: dict[str, dict[str, str]], notes: list[str],
                        design: Callable[..., tuple[np.ndarray, np.ndarray]]) -> Any:
    """``f`` as found, or ``not_identifiable`` when a settling at each slot of the visiting
    order takes its input-only term (module docstring). ``terms`` the accepted terms,
    ``design(pb, terms)`` the whitened design and data."""
    eff = BY_ID.get(f.effect)
    if eff is None or not eff.input_only or not f.named_as_modelled or f.rows:
        return f
    ctx = pb.ctx
    term = next((t for t in terms if t.key in f.term_keys), None)
    if term is None or len(ctx.step_ids) < MIN_STEPS:
        return f
    others = [t for t in terms if t is not term]
    # the size first: a long repeated schedule has a slot per visit (27,264 at 300 k
    # readings), and its (N, 3, 3·slots) columns alone would not fit in memory
    slot = visit_slots(ctx.steps, ctx.positions, ctx.t_s)
    n_columns = 3 * (int(slot.max()) + 1 if slot.size else 0)
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in others) + n_columns
    if 8 * pb.m * p > stats.TALL_BYTES or pb.m <= p + 10:
        notes.append(f"{f.effect}: not checked against a settling at each slot of the "
                     "visiting order: the recording is too long (or too short) for that "
                     "design")
        return f
    slots = slot_offset_columns(ctx.steps, ctx.positions, ctx.t_s)
    Xw, yw = design(pb, others)
    U0 = stats.orthonormal_basis(Xw)
    del Xw
    U, e = extend(U0, yw - U0 @ (U0.T @ yw), pb.whiten(pb.lift(slots)))
    lp, k = part_beyond(U, e, pb.whiten(term.X))
    if k > 0 and lp <= np.log(alpha):
        return f
    n_slot = slots.shape[2] // 3
    if time_and_position_confounded(ctx.steps, ctx.positions, ctx.t_s):
        why = ("the positions are visited in the same order on every plateau, so each "
               "position is also a fixed time within the plateau reached by a fixed move: "
               f"a free per-axis offset at each of the {n_slot} slots of the order fits "
               f"every function of the position, the {f.effect} term's included "
               f"({k} of its directions left beyond them)")
    else:
        why = ("the visiting order varies too little between the plateaus: after a free "
               f"per-axis offset at each of the {n_slot} slots of the order, the {f.effect} "
               f"term's part beyond them ({k} direction(s)) is not significant "
               f"(p = {np.exp(lp):.2g} > α)")
    return withheld(f, SLOT_SETTLING, why, EXPERIMENT, not_ident, slots=n_slot)
