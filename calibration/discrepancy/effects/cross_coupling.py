"""``cross_coupling``: products of two axes' inputs, one coefficient per axis pair (effects.md).

``raw_x += k_xy a_x a_y + k_xz a_x a_z`` and likewise (each pair couples into
both of its axes, as ``simulators/effects.py`` models it). Axis-aligned
positions make every product zero: not identifiable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, fmt_pm

PAIRS = (("xy", 0, 1), ("xz", 0, 2), ("yz", 1, 2))


def pair_products(a: np.ndarray) -> np.ndarray:
    """(N,3) inputs → (N,3,3): column k is pair k's product ``a_i a_j`` on both its axes."""
    out = np.zeros((a.shape[0], 3, 3))
    for k, (_, i, j) in enumerate(PAIRS):
        prod = a[:, i] * a[:, j]
        out[:, i, k] = prod
        out[:, j, k] = prod
    return out


def cross_coupling_g(a: np.ndarray, k_per_g: np.ndarray) -> np.ndarray:
    """Cross-coupling output change (N,3) g of inputs ``a`` (N,3) g; ``k_per_g`` (k_xy, k_xz, k_yz).

    effects.md: ``raw_x += k_xy a_x a_y + k_xz a_x a_z`` and likewise for y, z.
    The one place of this physics: the twin's truth effect and the model-file
    term (:meth:`CrossCoupling.extension_term_g`) both call it.
    """
    return pair_products(a) @ np.asarray(k_per_g, float)


@dataclass(frozen=True)
class CrossCoupling(CatalogueEffect):
    effect_id: str = "cross_coupling"
    twin_carries: bool = True
    confusers: tuple[str, ...] = ("scale_nonlinearity", "turntable_geometry")
    experiment: str = ("add oblique positions where two axes see gravity at once "
                       "(45° between axes, e.g. table1 or cube14)")
    writes_extension: bool = True
    extension_absorbed: bool = True
    input_only: bool = True
    checks_shape_after_turn: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return pair_products(ctx.input_g)

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        a = ctx.input_g
        top = max(float(np.max(np.abs(a[:, i] * a[:, j]))) for _, i, j in PAIRS)
        if top < 0.05:
            return (False, "axis-aligned positions only: every product of two axes' inputs is "
                    "zero", self.experiment)
        return True, "", self.experiment

    def shape_after_turn(self, pb: Any, U: np.ndarray, e: np.ndarray, axes: list[str],
                         alpha: float) -> dict[str, Any] | None:
        """An input dependence that products of two axes' inputs do not follow: a free
        offset per reference direction still needed after them and a turn (an ADC error
        confined to a band of codes took a share of the products, issue 22). After the turn
        check: a strong table tilt stood in for by the products (reported as a turn) changes
        the force's length at second order, which the turn columns do not carry. Then an
        offset per sweep of the table (:meth:`_offset_per_sweep`)."""
        from calibration.discrepancy.effects.scale_nonlinearity import direction_offsets_needed

        ax = tuple(AXES.index(a) for a in axes if a in AXES) or (0, 1, 2)
        found = direction_offsets_needed(pb, U, e, ax, alpha, "products of two axes' inputs")
        return found if found is not None else self._offset_per_sweep(pb, U, e, alpha)

    def _offset_per_sweep(self, pb: Any, U: np.ndarray, e: np.ndarray,
                          alpha: float) -> dict[str, Any] | None:
        """Where the references show the table's sweeps (``turntable_circles``): after the
        products, no constant offset per sweep may be needed (F, at α).

        Why (issue 22): a cable wound round the table's inner axis pulls by an amount set by
        that axis' angle, the same all along each sweep of the outer axis; products of the
        inputs took a share of it (4 of 300 unseen outside effects named
        ``cross_coupling``). A product of the inputs follows the reference along a sweep;
        a force set by the table does not. One offset vector per sweep (3 per circle) is a
        few dof against the free offset per direction's many, so it has the power where
        that one has not; with a true product term it is only noise.
        """
        from calibration.discrepancy.effects.structure import log_p, whitened
        from calibration.discrepancy.effects.turntable_circles import offset_columns
        from calibration.discrepancy.effects.turntable_geometry import sweep_layout

        ctx = pb.ctx
        _, axes, circle = sweep_layout(ctx)
        if not axes:
            return None
        lp, k = log_p(U, e, whitened(pb, offset_columns(ctx.n, circle, len(axes))))
        if k == 0 or lp > np.log(alpha):
            return None
        return {"kind": "visits",
                "positions": sorted(int(p) for p in np.unique(ctx.positions[circle >= 0])),
                "axes": ["x", "y", "z"], "log10_p": round(float(lp / np.log(10)), 1),
                "why": ("after the products of two axes' inputs, each sweep of the table "
                        "still needs an offset of its own: a force set by the table's angle "
                        "(e.g. a cable wound round an axis), not by the specific force")}

    def parameters(self, coef, se, theta, ctx):
        p = {f"k_{name}_ug_per_g2": float(coef[k] * UG) for k, (name, _, _) in enumerate(PAIRS)}
        s = {f"k_{name}_ug_per_g2": float(se[k] * UG) for k, (name, _, _) in enumerate(PAIRS)}
        return p, s

    def extension_fields(self, params):
        return {f"k_{name}_per_g": params[f"k_{name}_ug_per_g2"] * 1e-6 for name, _, _ in PAIRS}

    def extension_term_g(self, spec, a):
        k = np.array([float(spec.get(f"k_{name}_per_g", 0.0)) for name, _, _ in PAIRS])
        return cross_coupling_g(a, k)

    def axes(self, coef, se):
        z = np.abs(coef / np.where(se > 0, se, np.inf))
        hit: set[str] = set()
        for k, (name, _, _) in enumerate(PAIRS):
            if z[k] >= 3.0:
                hit.update(name)
        return sorted(hit) or list(PAIRS[int(np.argmax(z))][0])

    def sentence(self, params, sd, axes, ctx=None):
        names = sorted(params, key=lambda k: -abs(params[k]) / max(sd[k], 1e-12))
        top = names[0]
        pair = top.split("_")[1]
        return (f"the {pair[0]} and {pair[1]} outputs pick up the product of their two inputs: "
                f"K_{pair} = {fmt_pm(params[top], sd[top], 'µg/g²')}")
