"""``temperature_rate``: output ∝ dT/dt with free per-axis gains (effects.md).

Regressor: the rate of the recorded temperature (°C/min) at each reading, from a
parabola in time per plateau (:func:`reading_rate_c_per_min`), on each axis. A soak
measures at dT/dt ≈ 0, so it is often not identifiable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, axis_params, fmt_pm, per_axis

MIN_RATE_C_PER_MIN = 0.02
# Why so close to 1 (issue 22): on a plateau the die settles as dT/dt = (T_set − T)/τ, so a
# rate term is mostly a re-map of T that the cubic absorbs (99.5 % on a one-way or sparse
# staircase); what shows it is the remnant — each plateau's decay against the cubic's one
# slope — and its test (the same bootstrap null as every term) decides. The limit is the
# regressor's own error: the fitted parabola's rate is good to ~1 % (10⁻⁴ in norm²).
ABSORBED_MAX_RATE = 1.0 - 1e-4


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
    # thermal_hysteresis: on a plateau the die still settles towards the setpoint, so the
    # rate's sign is the direction of the last step; up-down, a rate term reads as ±h.
    confusers: tuple[str, ...] = ("thermal_lag", "session_offset", "thermal_hysteresis")
    experiment: str = ("record positions during slow ramps in both directions (e.g. ±0.5 °C/min) "
                       "with sensor_c as the temperature")
    told_apart: tuple[tuple[str, str], ...] = (
        ("thermal_hysteresis", "a rate term fades as the die settles within each plateau and "
                               "scales with the step's size; hysteresis persists at ±h"),)
    writes_extension: bool = True
    named_by_fit: bool = True
    absorbed_max: float = ABSORBED_MAX_RATE

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return per_axis(ctx, reading_rate_c_per_min(ctx))

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        top = float(np.max(np.abs(reading_rate_c_per_min(ctx)))) if ctx.n else 0.0
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


def reading_rate_c_per_min(ctx: DesignContext) -> np.ndarray:
    """dT/dt (°C/min) of the recorded temperature at each reading: the time derivative of
    a parabola in time fitted to its plateau's readings (a line on plateaus of 3 readings).

    Why not one slope per plateau (issue 22): on a plateau the die settles towards the
    setpoint, so dT/dt decays within it (by half over a 4-min plateau with τ = 5 min).
    What a rate effect leaves after the base model — whose cubic in T absorbs every
    plateau's mean — is that decay; a plateau's constant slope holds none of it, and a
    one-way staircase (all plateaus alike) then hid a rate effect at twice its detectable
    size entirely. The parabola is fitted, not differenced, so reading-to-reading noise of
    a quantised channel does not enter each reading's rate.
    """
    rate = np.zeros(ctx.n)
    for s in ctx.step_ids:
        m = np.flatnonzero(ctx.steps == s)
        t = ctx.t_s[m]
        if m.size < 3 or np.ptp(t) <= 0:
            continue
        dt = (t - t.mean()) / 60.0  # min
        deg = 2 if m.size >= MIN_READINGS_PARABOLA else 1
        c = np.polynomial.polynomial.polyfit(dt, ctx.temp_c[m], deg)
        rate[m] = c[1] + (2.0 * c[2] * dt if deg == 2 else 0.0)
    return rate


MIN_READINGS_PARABOLA = 6
