"""``bias_drift``: bias changing with elapsed time, not temperature (effects.md).

Regressor per axis: elapsed time in hours. In a one-way staircase time is
affine in temperature and the cubic absorbs it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, axis_params, fmt_pm, per_axis


def drift_offset_g(t_h: np.ndarray, rate_g_per_h: np.ndarray, relax_g: np.ndarray | float = 0.0,
                   relax_tau_h: float = 10.0) -> np.ndarray:
    """Bias drift (N,3) g at elapsed time ``t_h`` (N,) h (effects.md).

    ``rate_g_per_h · t_h + relax_g · (1 − exp(−t_h/relax_tau_h))``: the linear
    ramp is what this module regresses (its rate is ``rate_*_ug_per_h``); the
    relaxation is the twin's ageing term, which the ramp plus the cubic
    partly absorb. ``rate_g_per_h`` and ``relax_g`` one value or (3,).
    """
    t = np.asarray(t_h, float)[:, None]
    rate = np.broadcast_to(np.asarray(rate_g_per_h, float), (3,))
    relax = np.broadcast_to(np.asarray(relax_g, float), (3,))
    return rate * t + relax * (1.0 - np.exp(-t / relax_tau_h))


@dataclass(frozen=True)
class BiasDrift(CatalogueEffect):
    effect_id: str = "bias_drift"
    twin_carries: bool = True
    confusers: tuple[str, ...] = ("thermal_hysteresis", "thermal_lag", "session_offset")
    experiment: str = ("revisit a temperature hours later (e.g. a return step to the first "
                       "setpoint at the end) or hold one plateau for several hours")
    # Needs t_s, which compensate does not have: identity there, recorded for the twin.
    writes_extension: bool = True
    named_by_fit: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return per_axis(ctx, (ctx.t_s - ctx.t_s.min()) / 3600.0)

    def parameters(self, coef, se, theta, ctx):
        return axis_params("rate", "ug_per_h", coef, se, UG)

    def extension_fields(self, params):
        return {"rate_g_per_h": [params[f"rate_{a}_ug_per_h"] * 1e-6 for a in AXES]}

    def sentence(self, params, sd, axes, ctx=None):
        parts = [fmt_pm(params[f"rate_{a}_ug_per_h"], sd[f"rate_{a}_ug_per_h"], "µg/h")
                 for a in axes]
        if ctx is not None and ctx.temperature_source == "none":
            # Why: "not with temperature" needs a temperature to compare with.
            return (f"{'/'.join(axes)} bias drifts with elapsed time: {', '.join(parts)} (no "
                    "temperature is recorded, so a slow change of temperature would look the "
                    "same)")
        return (f"{'/'.join(axes)} bias drifts with elapsed time, not with temperature: "
                f"{', '.join(parts)}")
