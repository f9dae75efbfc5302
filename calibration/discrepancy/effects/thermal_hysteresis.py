"""``thermal_hysteresis``: ±h per axis by the direction of the last excursion (effects.md).

Regressor: direction (+1 after heating, −1 after cooling) on each axis. It
persists through the plateau (a lag decays with time since the step) and does
not grow with elapsed time (drift). A one-way staircase makes it constant:
the bias absorbs it entirely.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import UG, EffectModule, axis_params, fmt_pm, per_axis


@dataclass(frozen=True)
class ThermalHysteresis(EffectModule):
    effect_id: str = "thermal_hysteresis"
    confusers: tuple[str, ...] = ("thermal_lag", "bias_drift", "session_offset")
    experiment: str = ("revisit the same setpoints on a heating and a cooling leg "
                       "(e.g. −40 → 60 → −40 °C) so each temperature is seen from both sides")

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return per_axis(ctx, ctx.direction)

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if len(ctx.step_ids) < 2:
            return False, "one temperature plateau: there is no heating or cooling leg", \
                self.experiment
        if ctx.one_way or len(set(ctx.direction.tolist())) < 2:
            return (False, "every plateau is reached from the same side (one-way staircase): the "
                    "direction is constant and the bias absorbs ±h", self.experiment)
        return True, "", self.experiment

    def parameters(self, coef, se, theta, ctx):
        return axis_params("h", "ug", coef, se, UG)

    def sentence(self, params, sd, axes):
        parts = [fmt_pm(params[f"h_{a}_ug"], sd[f"h_{a}_ug"], "µg") for a in axes]
        return (f"{'/'.join(axes)} output reads higher after heating than after cooling at the "
                f"same temperature (half the difference h = {', '.join(parts)}), and it persists "
                "through each plateau")
