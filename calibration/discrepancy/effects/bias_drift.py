"""``bias_drift``: bias changing with elapsed time, not temperature (effects.md).

Regressor per axis: elapsed time in hours. In a one-way staircase time is
affine in temperature and the cubic absorbs it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import UG, EffectModule, axis_params, fmt_pm, per_axis


@dataclass(frozen=True)
class BiasDrift(EffectModule):
    effect_id: str = "bias_drift"
    confusers: tuple[str, ...] = ("thermal_hysteresis", "thermal_lag", "session_offset")
    experiment: str = ("revisit a temperature hours later (e.g. a return step to the first "
                       "setpoint at the end) or hold one plateau for several hours")

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return per_axis(ctx, (ctx.t_s - ctx.t_s.min()) / 3600.0)

    def parameters(self, coef, se, theta, ctx):
        return axis_params("rate", "ug_per_h", coef, se, UG)

    def sentence(self, params, sd, axes):
        parts = [fmt_pm(params[f"rate_{a}_ug_per_h"], sd[f"rate_{a}_ug_per_h"], "µg/h")
                 for a in axes]
        return (f"{'/'.join(axes)} bias drifts with elapsed time, not with temperature: "
                f"{', '.join(parts)}")
