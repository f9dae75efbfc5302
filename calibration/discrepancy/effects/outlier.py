"""``outlier``: a few readings far off, isolated in time (effects.md).

Tested per reading (an indicator on each axis, i.e. leave-the-row-out), the
max over readings calibrated by the null. Flagged readings are excluded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, EffectModule


def spike_mean_fraction(spike_samples: int | None, n_samples: np.ndarray) -> np.ndarray:
    """Fraction (N,) of a spike's size that reaches each recorded mean (effects.md).

    A recorded row averages ``n_samples``; a spike of ``size_g`` on
    ``spike_samples`` of them moves the mean by ``size_g · spike_samples / n``.
    ``spike_samples=None`` is a whole-reading disturbance (shock, door opened): 1.
    """
    n = np.asarray(n_samples, float)
    return np.ones(n.shape) if spike_samples is None else spike_samples / n


@dataclass(frozen=True)
class Outlier(EffectModule):
    effect_id: str = "outlier"
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

    def sentence(self, params, sd, axes, ctx=None):
        rows = params.get("rows") or [params["row"]]
        sizes = ", ".join(f"{ax} {params[f'size_{ax}_ug']:.0f} µg" for ax in axes)
        return (f"{len(rows)} reading(s) stand far off the rest and are isolated in time "
                f"(largest at t = {params['t_s']:.0f} s, step {int(params['step'])}, position "
                f"{int(params['position'])}: {sizes}); they are excluded")
