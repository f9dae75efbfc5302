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
        the force's length at second order, which the turn columns do not carry."""
        from calibration.discrepancy.effects.scale_nonlinearity import direction_offsets_needed

        ax = tuple(AXES.index(a) for a in axes if a in AXES) or (0, 1, 2)
        return direction_offsets_needed(pb, U, e, ax, alpha, "products of two axes' inputs")

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
