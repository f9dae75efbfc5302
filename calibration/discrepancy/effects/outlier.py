"""``outlier``: a few readings far off, isolated in time (effects.md).

Tested per reading (an indicator on each axis, i.e. leave-the-row-out), the
max over readings calibrated by the null. Flagged readings are excluded.
A flagged reading keeps the name only if it is isolated (:meth:`Outlier.misses`):
the other readings must not predict its deviation. A flagged reading whose recorded
temperature jumped off its neighbours and whose residual is the model's own ∂output/∂T is a
glitch of the temperature channel, not an outlier (:mod:`.channel_glitch`, issue 22).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect
from calibration.discrepancy.effects.structure import (
    extend,
    log_p,
    per_axis_indicator,
    whitened,
)

# Companions of a flagged reading, the other readings that would share its deviation if it
# were structure: at least this many (fewer predict nothing), and the nearest in time on
# its plateau (a transient is a reading or two; a drift or lag moves a plateau's run).
MIN_COMPANIONS = 3
TIME_NEIGHBOURS = 6


def spike_mean_fraction(spike_samples: int | None, n_samples: np.ndarray) -> np.ndarray:
    """Fraction (N,) of a spike's size that reaches each recorded mean (effects.md).

    A recorded row averages ``n_samples``; a spike of ``size_g`` on
    ``spike_samples`` of them moves the mean by ``size_g · spike_samples / n``.
    ``spike_samples=None`` is a whole-reading disturbance (shock, door opened): 1.
    """
    n = np.asarray(n_samples, float)
    return np.ones(n.shape) if spike_samples is None else spike_samples / n


@dataclass(frozen=True)
class Outlier(CatalogueEffect):
    effect_id: str = "outlier"
    twin_omitted: str = ("an event of this recording (a reading far off), not physics a new "
                         "campaign meets again")
    confusers: tuple[str, ...] = ("thermal_lag",)
    experiment: str = "repeat the flagged positions"
    per_reading: bool = True

    def grid(self, ctx: DesignContext) -> list[float]:
        return [float(i) for i in range(ctx.n)]

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        out = np.zeros((ctx.n, 3, 3))
        out[int(theta), [0, 1, 2], [0, 1, 2]] = 1.0
        return out

    def parameters(self, coef, se, theta, ctx):
        i = int(theta)
        p = {"row": float(i), "t_s": float(ctx.t_s[i]), "step": float(ctx.steps[i]),
             "position": float(ctx.positions[i])}
        s: dict[str, float] = {}
        for a, ax in enumerate(AXES):
            p[f"size_{ax}_ug"], s[f"size_{ax}_ug"] = float(coef[a] * UG), float(se[a] * UG)
        return p, s

    def misses(self, pb: Any, U: np.ndarray, e: np.ndarray, theta: float,
               where: Mapping[str, Any], axes: list[str], alpha: float) -> dict[str, Any] | None:
        """The structure a flagged reading belongs to, or None when it is isolated (issue 10).

        ``U``, ``e``: the model without the flagged readings' terms. For each kind of
        companion (:func:`companions`: its position at the other plateaus, a smooth
        function of the reference direction, its neighbours in time on its plateau) two
        single tests at α: (1) the companions' structure is significant with this reading
        left out (its indicator in the model): the others show it on their own; (2) the
        reading, tested as in selection (its indicator, Šidák over the readings) after that
        structure, no longer stands off. Both: its deviation is what the others predict,
        and it is part of that structure, not a transient. A true spike passes (1) only by
        chance (α) and keeps (2) but for its small leverage on the structure's fit.
        Companions that stand off alone (at most half of them) are left out of both tests,
        each by its own indicator: another outlier is no witness of a structure.
        """
        ctx = pb.ctx
        i = int(theta)
        off = readings_log_p(pb, U, e) <= np.log(alpha)
        if not off[i]:
            return None  # not an outlier by this test either: nothing to re-judge
        best: dict[str, Any] | None = None
        for kind, rows, X in companions(ctx, i):
            # The companions that stand off alone are candidates of this test too, not
            # witnesses of a structure: two outliers at one position (or close in time)
            # would otherwise each make the other's "structure" (issue 22: two disturbed
            # readings at two of the four visits of a position, both withdrawn). Left out
            # while they are at most half the companions: a structure most show stays one.
            others = rows[rows != i]
            held = others[off[others]]
            if held.size > others.size // 2:
                held = held[:0]
            if kind != "direction" and others.size - held.size < MIN_COMPANIONS:
                continue  # too few quiet companions left to predict anything
            Uh, eh = (U, e) if held.size == 0 else extend(U, e, whitened(pb, np.concatenate(
                [self.regressors(ctx, float(j)) for j in held], axis=2)))
            Ub, eb = extend(Uh, eh, whitened(pb, self.regressors(ctx, theta)))
            Xw = whitened(pb, X)
            lp_struct, k = log_p(Ub, eb, Xw)  # (1) the others alone
            if k == 0 or lp_struct > np.log(alpha):
                continue
            Ua, ea = extend(Uh, eh, Xw)
            if reading_log_p(pb, Ua, ea, i) <= np.log(alpha):  # (2) after the structure
                continue
            if best is None or lp_struct < best["log10_p"] * np.log(10):
                rows = _where_large(pb, Ub, eb, Xw, rows)
                best = {"kind": kind, "row": i, "step": int(ctx.steps[i]),
                        "position": int(ctx.positions[i]),
                        "positions": sorted({int(p) for p in ctx.positions[rows]}),
                        "steps": sorted({int(s) for s in ctx.steps[rows]}),
                        "time_s": [float(ctx.t_s[rows].min()), float(ctx.t_s[rows].max())],
                        "axes": list(axes),
                        "log10_p": round(float(lp_struct / np.log(10)), 1),
                        "why": _NOT_ISOLATED[kind]}
        return best

    def sentence(self, params, sd, axes, ctx=None):
        rows = params.get("rows") or [params["row"]]
        sizes = ", ".join(f"{ax} {params[f'size_{ax}_ug']:.0f} µg" for ax in axes)
        return (f"{len(rows)} reading(s) stand far off the rest and are isolated in time "
                f"(largest at t = {params['t_s']:.0f} s, step {int(params['step'])}, position "
                f"{int(params['position'])}: {sizes}); they are excluded")


def readings_log_p(pb: Any, U: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(N,) Šidák-adjusted log p of every reading's statistic after ``U`` (reading_log_p)."""
    dof = np.sqrt(pb.m / max(pb.m - U.shape[1], 1))
    s = float(stats.robust_scale(e[:, None], dof)[0])
    t, _, g = stats.row_stats(U, e, np.zeros((pb.m, 1)), pb.row, pb.ctx.n, s, np.ones(1),
                              set(), pb.shared_t_loading)
    return stats.sidak_log(stats.chi2_logsf(t, g), pb.ctx.n)


def reading_log_p(pb: Any, U: np.ndarray, e: np.ndarray, row: int) -> float:
    """Šidák-adjusted log p of one reading's leave-one-reading-out statistic after ``U``.

    The selection's statistic (stats.row_stats: robust MAD scale, the reading's block of
    the residual covariance with its shared temperature error, χ²_g) for one reading, its
    p adjusted for the number of readings searched; without the bootstrap, which calibrates
    the max over readings in selection, not this one reading's re-test.
    """
    return float(readings_log_p(pb, U, e)[row])


def _where_large(pb: Any, U: np.ndarray, e: np.ndarray, Xw: np.ndarray,
                 rows: np.ndarray) -> np.ndarray:
    """The readings of ``rows`` where the structure fitted to the others is at least half its
    largest (the oblique positions of a product term, not every reading)."""
    Z = stats.project_out(U, Xw)
    fit = Xw @ np.linalg.lstsq(Z, e, rcond=None)[0]
    per_row = np.sqrt(np.bincount(pb.row, fit**2, minlength=pb.ctx.n))[rows]
    return rows[per_row >= 0.5 * per_row.max()] if per_row.size and per_row.max() > 0 else rows


_NOT_ISOLATED = {
    "position": "the same position deviates alike at the other plateaus",
    "direction": "a smooth function of the reference direction (its orientation class) "
                 "fitted to the other readings predicts it",
    "time": "its neighbours in time on the same plateau deviate alike",
}


def companions(ctx: DesignContext, row: int) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(kind, rows, (N,3,k) columns) of each structure a reading at ``row`` may belong to.

    * ``position``: an offset per axis at the reading's position over the whole campaign
      (a product of axes, a mounting or history effect repeats there at every plateau);
    * ``direction``: per axis, the second-order monomials of the reference direction (a
      smooth function of it: an orientation class such as the oblique positions);
    * ``time``: an offset per axis on the reading and its nearest readings in time on its
      plateau (a drift, a lag or settling moves a run of readings, a transient one).

    Each includes the reading itself, so the structure fitted to all predicts it; a
    kind with fewer than :data:`MIN_COMPANIONS` other readings is skipped.
    """
    n = ctx.n
    out: list[tuple[str, np.ndarray, np.ndarray]] = []
    same_pos = np.flatnonzero(ctx.positions == ctx.positions[row])
    if same_pos.size - 1 >= MIN_COMPANIONS:
        out.append(("position", same_pos, per_axis_indicator(n, same_pos)))
    a = ctx.input_g
    quad = [a[:, i] * a[:, j] for i in range(3) for j in range(i, 3)]
    X = np.zeros((n, 3, 3 * len(quad)))
    for ax in range(3):
        for k, col in enumerate(quad):
            X[:, ax, ax * len(quad) + k] = col
    out.append(("direction", np.arange(n), X))
    plateau = np.flatnonzero(ctx.steps == ctx.steps[row])
    near = plateau[np.argsort(np.abs(ctx.t_s[plateau] - ctx.t_s[row]), kind="stable")]
    near = np.sort(near[:TIME_NEIGHBOURS + 1])
    if near.size - 1 >= MIN_COMPANIONS:
        out.append(("time", near, per_axis_indicator(n, near)))
    return out
