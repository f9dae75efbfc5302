"""``thermal_lag``: the die follows the chamber air through a first-order lag τ (effects.md).

Regressor: ``−(∂raw/∂T)·(T_recorded − T_die)`` = ``(∂raw/∂T)·(T_die − T_air)``
with ``T_die`` the recorded air temperature through a first-order lag of τ.
The gain is locked to the model's own ∂raw/∂T (one τ, no free gain): that is
what tells a lag from ``temperature_rate`` (free gains) and from hysteresis
(persists through the plateau) or drift (grows with elapsed time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import EffectModule

RAMP_C_PER_MIN = 2.0  # assumed chamber ramp between steps (seed Table 3: 0.1–5 °C/min)
AMBIENT_C = 25.0  # assumed start of the campaign: the die at lab ambient before the first ramp
TAU_GRID_S = tuple(float(v) for v in np.geomspace(120.0, 14400.0, 18))


@dataclass(frozen=True)
class ThermalLag(EffectModule):
    effect_id: str = "thermal_lag"
    confusers: tuple[str, ...] = ("thermal_hysteresis", "temperature_rate", "bias_drift")
    experiment: str = ("fit on the chamber air temperature (chamber_c) with soaks shorter than "
                       "3 τ, or log the die with an external probe and compare")
    fixed_gain: bool = True

    def grid(self, ctx: DesignContext) -> list[float]:
        return list(TAU_GRID_S)

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        dT = die_minus_air_c(ctx, theta)
        return (ctx.draw_dtemp_g_per_c * dT[:, None])[:, :, None]

    def nuisance(self, ctx: DesignContext, theta: float) -> np.ndarray:
        """The first plateau's starting die temperature is unknown: a free decaying column.

        Why: the recording does not say where the die was before the first plateau;
        a wrong guess would be read as a jump at step 1 (session offset).
        """
        first = ctx.steps == ctx.step_ids[0]
        decay = np.where(first, np.exp(-(ctx.t_s - ctx.t_s[first].min()) / theta), 0.0)
        return (ctx.draw_dtemp_g_per_c * decay[:, None])[:, :, None]

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if ctx.temperature_source == "none" or len(ctx.step_ids) < 2:
            return False, "one temperature plateau (or none recorded): no step to lag behind", \
                self.experiment
        if ctx.temperature_source == "sensor_c":
            return (False, "the model's temperature is the sensor's own channel, which follows "
                    "the die: a chamber-to-die lag is already inside the regressor",
                    self.experiment)
        return True, "", self.experiment

    def parameters(self, coef, se, theta, ctx):
        return {"tau_s": float(theta)}, {"tau_s": float(se[0]) if se.size else float("nan")}

    def axes(self, coef, se):
        return ["x", "y", "z"]

    def sentence(self, params, sd, axes):
        tau, s = params["tau_s"], sd.get("tau_s", float("nan"))
        unc = f" (≈ {s:.0f} s)" if np.isfinite(s) else ""
        return (f"the sensor die lags the chamber air with a time constant τ = {tau:.0f} s{unc}: "
                "readings early in each plateau still carry part of the last step, scaled by the "
                "model's own temperature sensitivity")


def die_minus_air_c(ctx: DesignContext, tau_s: float) -> np.ndarray:
    """T_die − T_air at each reading for a first-order lag τ of a reconstructed air history.

    The air history: each plateau at its median temperature; between plateaus a
    ramp at :data:`RAMP_C_PER_MIN` starting at the previous plateau's last reading
    (why: the recording does not hold the ramp; the ramp is short next to τ).
    Before the first plateau the campaign is assumed to start at
    :data:`AMBIENT_C` and to ramp, then soak as long as the other plateaus do.
    """
    ids = ctx.step_ids
    t = ctx.t_s
    first = {s: float(t[ctx.steps == s].min()) for s in ids}
    last = {s: float(t[ctx.steps == s].max()) for s in ids}
    dt = max(min(tau_s / 10.0, 20.0), 1.0)
    rate = RAMP_C_PER_MIN / 60.0
    soaks = [first[ids[k]] - last[ids[k - 1]]
             - abs(ctx.step_temp_c[ids[k]] - ctx.step_temp_c[ids[k - 1]]) / rate
             for k in range(1, len(ids))]
    soak = max(float(np.median(soaks)), 0.0) if soaks else 0.0
    a0, b0 = AMBIENT_C, ctx.step_temp_c[ids[0]]
    t0 = first[ids[0]] - soak - abs(b0 - a0) / rate
    grid = np.arange(t0, float(t.max()) + dt, dt)
    air = a0 + np.sign(b0 - a0) * np.minimum(rate * (grid - t0), abs(b0 - a0))
    for k in range(1, len(ids)):
        a, b = ctx.step_temp_c[ids[k - 1]], ctx.step_temp_c[ids[k]]
        start = last[ids[k - 1]]
        m = grid > start
        ramp = a + np.sign(b - a) * np.minimum(rate * (grid[m] - start), abs(b - a))
        air[m] = ramp
    alpha = float(np.exp(-dt / tau_s))
    die = lfilter([1.0 - alpha], [1.0, -alpha], air, zi=[alpha * air[0]])[0]
    return np.interp(t, grid, die) - np.interp(t, grid, air)
