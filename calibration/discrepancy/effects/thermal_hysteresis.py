"""``thermal_hysteresis``: ±h per axis by the direction of the last excursion (effects.md).

Regressor: direction (+1 after heating, −1 after cooling) on each axis. It
persists through the plateau (a lag decays with time since the step) and does
not grow with elapsed time (drift). A one-way staircase makes it constant:
the bias absorbs it entirely.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import (
    UG,
    CatalogueEffect,
    axis_params,
    fmt_pm,
    per_axis,
    vec3,
)


def hysteresis_offset_g(direction: np.ndarray | float, h_g: np.ndarray) -> np.ndarray:
    """Hysteresis output change g: ``direction × h_g`` per axis (effects.md).

    ``direction`` is +1 after heating, −1 after cooling, 0 before any excursion,
    per reading (N,) → (N,3) or one value → (3,). ``h_g`` one value or (3,).
    The one place of this physics: the twin and the model-file term both call it.
    """
    h = np.broadcast_to(np.asarray(h_g, float), (3,))
    return np.asarray(direction, float)[..., None] * h


@dataclass(frozen=True)
class ThermalHysteresis(CatalogueEffect):
    effect_id: str = "thermal_hysteresis"
    twin_carries: bool = True
    confusers: tuple[str, ...] = ("thermal_lag", "bias_drift", "session_offset")
    experiment: str = ("revisit the same setpoints on a heating and a cooling leg "
                       "(e.g. −40 → 60 → −40 °C) so each temperature is seen from both sides")
    told_apart: tuple[tuple[str, str], ...] = (
        ("bias_drift", "hysteresis flips with heating/cooling at revisited temperatures; "
                       "drift is monotonic in time"),)
    writes_extension: bool = True
    named_by_fit: bool = True

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

    def extension_fields(self, params):
        # ``direction``: set +1/−1 for the leg being compensated (0: no correction).
        return {"h_g": [params[f"h_{a}_ug"] * 1e-6 for a in AXES], "direction": 0.0}

    def extension_term_g(self, spec, a):
        d = float(spec.get("direction", 0.0))
        return np.broadcast_to(hysteresis_offset_g(d, vec3(spec, "h_g"))[None, :], a.shape)

    def sentence(self, params, sd, axes, ctx=None):
        parts = [fmt_pm(params[f"h_{a}_ug"], sd[f"h_{a}_ug"], "µg") for a in axes]
        # Why the sign: h is the coefficient of +1 after heating; a negative h reads lower.
        signs = {np.sign(params[f"h_{a}_ug"]) for a in axes}
        how = "higher" if signs == {1.0} else "lower" if signs == {-1.0} else "differently"
        return (f"{'/'.join(axes)} output reads {how} after heating than after cooling at the "
                f"same temperature (half the difference h = {', '.join(parts)}), and it persists "
                "through each plateau")
