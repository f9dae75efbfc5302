"""``scale_nonlinearity``: own-axis a² and a³ terms (effects.md).

Regressors per axis: ``a_i²`` and ``a_i³`` with a_i the input on axis i.
Axis-aligned positions alias a³ into scale (a³ = a) and a² partly into bias;
the absorbed fraction measures that.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, fmt_pm, vec3
from calibration.discrepancy.effects.structure import (
    direction_ids,
    extend,
    extend_by_rows,
    fitted_after,
    fitted_by_labels,
    log_p,
    log_p_by_labels,
    log_p_by_plateau,
    per_axis_indicator,
    whitened,
)


def own_powers(a: np.ndarray) -> np.ndarray:
    """(N,3) inputs → (N,3,6): ``a_i²`` (columns 0–2) and ``a_i³`` (3–5) on axis i."""
    out = np.zeros((a.shape[0], 3, 6))
    for i in range(3):
        out[:, i, i] = a[:, i] ** 2
        out[:, i, 3 + i] = a[:, i] ** 3
    return out


def scale_nonlinearity_g(a: np.ndarray, k2_per_g: np.ndarray, k3_per_g2: np.ndarray) -> np.ndarray:
    """Own-axis nonlinearity output change (N,3) g: ``K2_i a_i² + K3_i a_i³`` (effects.md).

    ``a`` (N,3) g, ``k2_per_g`` and ``k3_per_g2`` one value or (3,). The one place
    of this physics: the twin's truth effect and the model-file term
    (:meth:`ScaleNonlinearity.extension_term_g`) both call it.
    """
    k2 = np.broadcast_to(np.asarray(k2_per_g, float), (3,))
    k3 = np.broadcast_to(np.asarray(k3_per_g2, float), (3,))
    return own_powers(a) @ np.concatenate([k2, k3])


@dataclass(frozen=True)
class ScaleNonlinearity(CatalogueEffect):
    effect_id: str = "scale_nonlinearity"
    twin_carries: bool = True
    confusers: tuple[str, ...] = ("cross_coupling", "bias_drift")
    experiment: str = ("add oblique positions (e.g. the cube14 diagonals) so a³ and a² differ "
                       "from scale and bias")
    told_apart: tuple[tuple[str, str], ...] = (
        ("cross_coupling", "own-axis a², a³ versus products of two axes' inputs"),)
    writes_extension: bool = True
    extension_absorbed: bool = True
    input_only: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return own_powers(ctx.input_g)

    def misses(self, pb: Any, U: np.ndarray, e: np.ndarray, theta: float,
               where: Mapping[str, Any], axes: list[str], alpha: float) -> dict[str, Any] | None:
        """Visits that differ (the input-only check), or an input dependence that is not a
        bend: :func:`bends_otherwise`."""
        found = super().misses(pb, U, e, theta, where, axes, alpha)
        return found if found is not None else bends_otherwise(pb, U, e, axes, alpha)

    def parameters(self, coef, se, theta, ctx):
        p, s = {}, {}
        for i, ax in enumerate(AXES):
            p[f"k2_{ax}_ug_per_g2"], s[f"k2_{ax}_ug_per_g2"] = coef[i] * UG, se[i] * UG
            p[f"k3_{ax}_ug_per_g3"], s[f"k3_{ax}_ug_per_g3"] = coef[3 + i] * UG, se[3 + i] * UG
        return ({k: float(v) for k, v in p.items()}, {k: float(v) for k, v in s.items()})

    def extension_fields(self, params):
        return {"k2_per_g": [params[f"k2_{a}_ug_per_g2"] * 1e-6 for a in AXES],
                "k3_per_g2": [params[f"k3_{a}_ug_per_g3"] * 1e-6 for a in AXES]}

    def extension_term_g(self, spec, a):
        return scale_nonlinearity_g(a, vec3(spec, "k2_per_g"), vec3(spec, "k3_per_g2"))

    def axes(self, coef, se):
        z = np.abs(coef / np.where(se > 0, se, np.inf)).reshape(2, 3)
        hit = [AXES[a] for a in range(3) if np.max(z[:, a]) >= 3.0]
        return hit or list(AXES)  # jointly significant, no axis resolved

    def stated_axes(self, pb, coef, se, alpha):
        """The axes the bend is judged on (:func:`bend_axes`), and what the finding says of
        the term's own axes when those hold too few input levels to show it (issue 22: a
        bend shown on x and y was stated as z's K2, which a band of codes on z makes too)."""
        resolved = self.axes(coef, se)
        b = bend_axes(pb, resolved, alpha)
        if not b.moved:
            return resolved, ""
        return [AXES[a] for a in b.axes], moved_clause(b)

    def sentence(self, params, sd, axes, ctx=None):
        z = {k: abs(v) / max(sd.get(k, 0.0), 1e-12) for k, v in params.items()}
        if max(z.values()) < 3.0:  # jointly significant, no single coefficient resolved
            top = max(z, key=z.__getitem__)
            unit = "µg/g²" if top.startswith("k2") else "µg/g³"
            return ("the outputs bend with their input (second/third-order terms, significant "
                    "together but not resolved coefficient by coefficient; largest "
                    f"{top} = {fmt_pm(params[top], sd[top], unit)})")
        return "; ".join(_axis_part(ax, params, sd) for ax in axes)


def _axis_part(ax: str, params: Mapping[str, float], sd: Mapping[str, float]) -> str:
    """One axis's bend in words: its resolved coefficient (the larger in sd), or both when
    neither is resolved alone (an axis the bend is judged on by its a², a³ together,
    :meth:`ScaleNonlinearity.stated_axes`; issue 22)."""
    k2, s2 = params[f"k2_{ax}_ug_per_g2"], sd[f"k2_{ax}_ug_per_g2"]
    k3, s3 = params[f"k3_{ax}_ug_per_g3"], sd[f"k3_{ax}_ug_per_g3"]
    z2, z3 = abs(k2) / max(s2, 1e-12), abs(k3) / max(s3, 1e-12)
    if max(z2, z3) < 3.0:
        return (f"{ax} output bends with its input (its a² and a³ terms together, neither "
                f"resolved alone): K2 = {fmt_pm(k2, s2, 'µg/g²')}, "
                f"K3 = {fmt_pm(k3, s3, 'µg/g³')}")
    if z2 >= z3:
        return f"{ax} output grows with the square of its input: K2 = {fmt_pm(k2, s2, 'µg/g²')}"
    return f"{ax} output grows with the cube of its input: K3 = {fmt_pm(k3, s3, 'µg/g³')}"


BEND_FUNCTIONS = 4  # 1, a, a², a³: the base's bias and scale and the bend's two terms
LEVEL_G = 0.05  # inputs closer than this on an axis are one level


def input_levels(a_g: np.ndarray) -> int:
    """Distinct levels of one axis's input (within :data:`LEVEL_G`)."""
    v = np.sort(np.asarray(a_g, float))
    return int(1 + np.sum(np.diff(v) > LEVEL_G)) if v.size else 0


def _own_log10_p(pb: Any, ax: tuple[int, ...]) -> float | None:
    """log10 p of the a², a³ columns on axes ``ax`` after the base model alone (single test)."""
    if 8 * pb.m * pb.X0.shape[1] > stats.TALL_BYTES:
        return None
    U0 = stats.orthonormal_basis(pb.whiten(np.asarray(pb.X0)))
    yw = pb.y * pb.w
    cols = own_powers(pb.ctx.input_g)[:, :, [c for a in ax for c in (a, 3 + a)]]
    lp, k = log_p(U0, yw - U0 @ (U0.T @ yw), whitened(pb, cols))
    return round(float(lp / np.log(10)), 1) if k else None


def level_columns(a_g: np.ndarray, axis: int) -> np.ndarray:
    """(N,3,L): a free output on ``axis`` at each of its input levels (:data:`LEVEL_G`
    apart), any function of that axis's input."""
    v = np.asarray(a_g, float)
    lv = np.concatenate([[0], np.cumsum(np.diff(np.sort(v)) > LEVEL_G)])
    ids = np.empty(v.size, int)
    ids[np.argsort(v)] = lv
    out = np.zeros((v.size, 3, int(ids.max()) + 1 if v.size else 0))
    out[np.arange(v.size), axis, ids] = 1.0
    return out


def _beyond_levels_log10_p(pb: Any, many: tuple[int, ...]) -> float | None:
    """log10 p of the a², a³ columns on axes ``many`` (each with more than
    :data:`BEND_FUNCTIONS` input levels) after the base model and any function of each
    other axis's own input levels (single test), or None (no such axis, or too tall)."""
    if not many:
        return None
    a = pb.ctx.input_g
    few = [level_columns(a[:, i], i) for i in range(3) if i not in many]
    cols = own_powers(a)[:, :, [c for i in many for c in (i, 3 + i)]]
    k0 = pb.X0.shape[1] + sum(f.shape[2] for f in few)
    if 8 * pb.m * (k0 + cols.shape[2]) > stats.TALL_BYTES:
        return None
    U0 = stats.orthonormal_basis(np.hstack([pb.whiten(np.asarray(pb.X0))]
                                           + [whitened(pb, f) for f in few]))
    yw = pb.y * pb.w
    lp, k = log_p(U0, yw - U0 @ (U0.T @ yw), whitened(pb, cols))
    return float(lp / np.log(10)) if k else None


@dataclass(frozen=True)
class BendAxes:
    """Where a recording judges a bend of the a², a³ term (issue 22; :func:`bend_axes`).

    ``axes``: the axes the bend is judged on (indices). ``few``: those of the term's axes
    that hold at most :data:`BEND_FUNCTIONS` input levels, with their levels (they cannot
    show a bend); empty in the ordinary case. ``log10_p``: the test that showed the bend on the
    axes with more levels instead (:func:`_beyond_levels_log10_p`), or None.
    """

    axes: tuple[int, ...]
    few: dict[int, int]
    log10_p: float | None = None

    @property
    def moved(self) -> bool:
        """Judged on the axes with more input levels than some of the term's own hold."""
        return bool(self.few) and self.log10_p is not None

    @property
    def withheld(self) -> bool:
        """Too few levels on some of the term's axes and no axis with more shows the bend."""
        return bool(self.few) and self.log10_p is None


def bend_axes(pb: Any, axes: list[str], alpha: float) -> BendAxes:
    """The axes on which this recording judges a bend of the term resolved on ``axes``.

    The one place of that choice (issue 22): :func:`bends_otherwise` tests the bend there,
    and the finding names them (:meth:`ScaleNonlinearity.stated_axes`), so a bend shown on
    x and y is not reported as z's coefficients. Ordinarily the term's own axes. Where any of
    them holds at most :data:`BEND_FUNCTIONS` input levels (Table-1-like sparse schedules: |a_z|
    of 0.5 and 1 g only), bias, scale, a² and a³ fit *any* function of that input and
    cannot show a bend; the axes with more levels may (a sparse schedule's x and y hold 5):
    their a², a³ after the base and any function of the other axes' levels, at α. Reference
    mode only (a bend per axis needs the axes); otherwise the term's axes.
    """
    ax = tuple(AXES.index(a) for a in axes if a in AXES) or (0, 1, 2)
    if pb.mode != "reference":
        return BendAxes(ax, {})
    a_g = pb.ctx.input_g
    few = {a: n for a in ax if (n := input_levels(a_g[:, a])) <= BEND_FUNCTIONS}
    if not few:
        return BendAxes(ax, {})
    # Any of the term's axes with too few levels (all of them, or z beside y: its
    # coefficients would be stated as a bend whatever made them): judged on the axes with
    # more levels after any function of the others', as where all are few.
    many = tuple(a for a in range(3) if input_levels(a_g[:, a]) > BEND_FUNCTIONS)
    lp = _beyond_levels_log10_p(pb, many)
    if lp is not None and lp <= np.log10(alpha):
        return BendAxes(many, few, round(lp, 1))
    return BendAxes(ax, few)


def _names(ax: Any) -> str:
    """Axis indices as words: "z", "x and y"."""
    n = [AXES[a] for a in ax]
    return n[0] if len(n) == 1 else ", ".join(n[:-1]) + " and " + n[-1]


def moved_clause(b: BendAxes) -> str:
    """What a finding judged on other axes than its term's says of both (issue 22)."""
    others = tuple(a for a in range(3) if a not in b.axes)
    few = tuple(b.few)
    shown = ", ".join(f"{AXES[a]}: {n}" for a, n in b.few.items())
    return (f"shown on {_names(b.axes)} (their a² and a³ after any function of "
            f"{_names(others)}'s input levels: log10 p = {b.log10_p}); {_names(few)}, where "
            f"the term's coefficients are resolved, {'holds' if len(few) == 1 else 'hold'} "
            f"too few input levels to resolve a bend ({shown}; bias, scale, a² and a³ fit "
            f"any function of up to {BEND_FUNCTIONS} levels): "
            f"{'its' if len(few) == 1 else 'their'} coefficients fit those levels whatever "
            "their cause (a bend, or a converter error confined to a band of codes) and are "
            "not stated as a bend")


def bends_otherwise(pb: Any, U: np.ndarray, e: np.ndarray, axes: list[str],
                    alpha: float) -> dict[str, Any] | None:
    """An input dependence the own-axis a², a³ do not describe, or None (issue 22).

    ``U``, ``e``: the model with the nonlinearity. A free offset per reference direction on
    the axes the bend is judged on (:func:`bend_axes`: ordinarily the term's), the same at
    every plateau, is tested after the model and a turn of the reference
    (``turntable_geometry.turn_columns``, whose own confusion with a bend is judged apart).
    A smooth bend of the output with its input leaves nothing there but noise (the test
    rejects with probability α); a converter error confined to a band of codes (an offset
    at the directions whose input falls in the band, none at those on either side) or any
    other non-polynomial function of the direction does, and the a², a³ term then took only
    the share of it a parabola can carry. Where the term's axes see too few input levels and
    no other axis shows the bend, the structure is reported where it is, not named.
    Reference mode only (a direction's offset per axis needs the axes). Returns the place
    (positions, axes, log10 p).
    """
    if pb.mode != "reference":
        return None
    b = bend_axes(pb, axes, alpha)
    if b.withheld:
        shown = ", ".join(f"{AXES[a]}: {n}" for a, n in b.few.items())
        return {"positions": sorted({int(p) for p in pb.ctx.positions}),
                "axes": [AXES[a] for a in b.axes], "log10_p": _own_log10_p(pb, b.axes),
                "why": (f"the structure is a function of each axis's own input, but the "
                        f"protocol holds too few input levels on the term's axes ({shown}; "
                        f"bias, scale, a² and a³ fit any function of up to {BEND_FUNCTIONS} "
                        "levels): a "
                        "bend cannot be told from any other input dependence there, e.g. a "
                        "converter error confined to a band of codes (positions with more "
                        "input levels on those axes, such as oblique ones, tell them apart)")}
    return direction_offsets_needed(pb, U, e, b.axes, alpha, "own-axis a² and a³ terms")


def direction_offsets_needed(pb: Any, U: np.ndarray, e: np.ndarray, ax: tuple[int, ...],
                             alpha: float, term_words: str) -> dict[str, Any] | None:
    """The place where a free offset per reference direction on axes ``ax`` is still
    needed after the model (``U``, ``e``) and a turn of the reference, or None.

    An input-only term (``term_words``: what its columns are) that describes the input
    dependence leaves nothing there but noise (rejected with probability α); a converter
    error confined to a band of codes, which such a term takes only a share of, does.
    Reference mode only; at least 8 distinct directions.
    """
    if pb.mode != "reference":
        return None
    from calibration.discrepancy.effects.turntable_geometry import turn_columns

    ctx = pb.ctx
    dirs = direction_ids(ctx.positions, ctx.input_g)
    n_dir = int(dirs.max()) + 1
    if n_dir < 8:  # the base's 4 columns and the bend's 2 per axis leave nothing to test
        return None
    u = ctx.input_g / np.linalg.norm(ctx.input_g, axis=1, keepdims=True)
    n_turn = turn_columns(u[:1]).shape[2]
    if 8 * pb.m * n_turn > stats.TALL_BYTES and pb.m > 20 * n_turn:
        # A long recording (issue 22, memory): the turn's columns by row blocks and the
        # direction offsets in their own space, the dense form's test with one noise scale
        # for the recording (scaling each plateau by its own, as below, would need the
        # model's basis again: an (m × r) array).
        Ut, et = extend_by_rows(U, e, _turn_rows(pb, u), n_turn)
        labels = np.full(pb.m, -1)
        on = np.isin(pb.axis, ax)
        slot = np.full(3, -1)
        slot[list(ax)] = np.arange(len(ax))  # the dense columns' order: direction, then axis
        labels[on] = len(ax) * dirs[pb.row[on]] + slot[pb.axis[on]]
        lp, k = log_p_by_labels(pb, Ut, et, labels, len(ax) * n_dir)
        if k == 0 or lp > np.log(alpha):
            return None
        fit = fitted_by_labels(pb, Ut, et, labels, len(ax) * n_dir)
    else:
        X = np.concatenate([per_axis_indicator(ctx.n, np.flatnonzero(dirs == j), ax)
                            for j in range(n_dir)], axis=2)
        Ut, et = extend(U, e, whitened(pb, turn_columns(u)))
        Xw = whitened(pb, X)
        # Each plateau at its own noise scale (issue 22: one scale ran the test above its
        # level where plateaus are whitened unevenly; structure.log_p_by_plateau).
        lp, k = log_p_by_plateau(pb, Ut, et, Xw)
        if k == 0 or lp > np.log(alpha):
            return None
        fit = fitted_after(Ut, et, Xw)
    # Where: the directions whose fitted offset is at least half the largest.
    per_dir = np.sqrt(np.bincount(dirs[pb.row], fit**2, minlength=n_dir)
                      / np.maximum(np.bincount(dirs, minlength=n_dir), 1))
    big = np.flatnonzero(per_dir >= 0.5 * per_dir.max())
    return {"positions": sorted({int(p) for p in ctx.positions[np.isin(dirs, big)]}),
            "axes": [AXES[a] for a in ax], "log10_p": round(float(lp / np.log(10)), 1),
            "why": (f"the output depends on the reference direction in a way {term_words} "
                    "do not follow (a free offset per direction is still needed "
                    "after them and a turn of the reference): e.g. a converter error "
                    "confined to a band of codes")}


def _turn_rows(pb: Any, u: np.ndarray) -> Any:
    """Rows i:j of the whitened, lifted turn columns (``turn_columns(u)``, reference mode:
    residual row 3·reading + axis), built for those readings only."""
    from calibration.discrepancy.effects.turntable_geometry import turn_columns

    def rows(i: int, j: int) -> np.ndarray:
        a, b = i // 3, -(-j // 3)
        x = turn_columns(u[a:b]).reshape(3 * (b - a), -1)[i - 3 * a : j - 3 * a]
        return x * pb.w[i:j, None]

    return rows
