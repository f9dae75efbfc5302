"""``temperature_rate``: output ∝ dT/dt with free per-axis gains (effects.md).

Regressor: the within-plateau slope of the recorded temperature (°C/min) on
each axis. A soak measures at dT/dt ≈ 0, so it is usually not identifiable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, axis_params, fmt_pm, per_axis

MIN_RATE_C_PER_MIN = 0.02


def rate_offset_g(rate_c_per_time: np.ndarray, k_g_per_c_per_time: np.ndarray) -> np.ndarray:
    """Temperature-rate output change (N,3) g: ``k_i × dT/dt`` per axis (effects.md).

    The units of time cancel: a rate in °C/s takes gains in g per °C/s (the twin,
    on the die rate) and °C/min takes g per °C/min (this module's regressor, on
    the recorded slope). ``k`` one value or (3,).
    """
    k = np.broadcast_to(np.asarray(k_g_per_c_per_time, float), (3,))
    return np.asarray(rate_c_per_time, float)[:, None] * k[None, :]


@dataclass(frozen=True)
class TemperatureRate(CatalogueEffect):
    effect_id: str = "temperature_rate"
    # session_offset: in a one-way staircase the rate is largest on the first plateau and of
    # one sign, i.e. a jump after it (issue 10; protocol.py withholds the name then).
    confusers: tuple[str, ...] = ("thermal_lag", "session_offset")
    experiment: str = ("record positions during slow ramps in both directions (e.g. ±0.5 °C/min) "
                       "with sensor_c as the temperature")
    writes_extension: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return per_axis(ctx, ctx.rate_c_per_min)

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        top = float(np.max(np.abs(ctx.rate_c_per_min))) if ctx.n else 0.0
        if top < MIN_RATE_C_PER_MIN:
            return (False, f"readings are taken at dT/dt ≈ 0 (largest plateau slope "
                    f"{top:.3f} °C/min)", self.experiment)
        return True, "", self.experiment

    def parameters(self, coef, se, theta, ctx):
        return axis_params("k_rate", "ug_per_c_per_min", coef, se, UG)

    def sentence(self, params, sd, axes, ctx=None):
        parts = [fmt_pm(params[f"k_rate_{a}_ug_per_c_per_min"],
                        sd[f"k_rate_{a}_ug_per_c_per_min"], "µg per °C/min") for a in axes]
        return f"{'/'.join(axes)} output follows the rate of temperature change: {', '.join(parts)}"
