"""``temperature_rate``: output ∝ dT/dt with free per-axis gains (effects.md).

Regressor: the rate of the recorded temperature (°C/min) at each reading, from a
parabola in time per plateau (:func:`reading_rate_c_per_min`), on each axis. A soak
measures at dT/dt ≈ 0, so it is often not identifiable.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

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
    twin_carries: bool = True
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

    def misses(self, pb: Any, U: np.ndarray, e: np.ndarray, theta: float,
               where: Mapping[str, Any], axes: list[str], alpha: float) -> dict[str, Any] | None:
        """One gain on every plateau: :func:`gain_differs_between_plateaus`."""
        return gain_differs_between_plateaus(pb, U, e, axes, alpha)

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


# --- lag check (issue 22) -----------------------------------------------------------------
# A temperature channel lagging the die by τ (or a die lagging the chamber channel) reads
# T − τ·dT/dt, so the base model misses ∂f/∂T·τ·dT/dt on each axis: a rate term whose three
# gains are locked to the model's own temperature slope (effects.md: the confuser "lag, gain
# locked to ∂output/∂T"). The free per-axis gains are named only when they depart from that
# locked pattern beyond noise.
LAG_EXPERIMENT = ("record a die temperature independent of the channel (an external probe on "
                  "the package) and compare, or run rates at temperatures where ∂output/∂T "
                  "differs in sign between axes, so that a lag's locked gains and free gains "
                  "part")


def locked_lag_columns(ctx: DesignContext) -> np.ndarray:
    """(N,3,1) raw output change per minute of lag: ``∂raw/∂T × dT/dt`` on each axis.

    Its coefficient is τ in minutes (> 0: the temperature regressor lags the die).
    """
    return (ctx.draw_dtemp_g_per_c * reading_rate_c_per_min(ctx)[:, None])[:, :, None]


@dataclass(frozen=True)
class LagCheck:
    """The free rate against the locked one: F test of the free gains after the lag."""

    log_p_free: float  # log p of the free per-axis gains once the locked lag is in the model
    dof: int
    tau_s: float
    tau_sd_s: float


def lag_check(pb: Any, U_others: np.ndarray, e_others: np.ndarray) -> LagCheck:
    """Test the free rate columns after the locked lag column (whitened, F at the data).

    ``U_others``/``e_others``: orthonormal basis and residual of the model without the rate
    term (base plus every other accepted term). The lag's τ is its least-squares fit there.
    """
    from calibration.discrepancy import stats

    ctx = pb.ctx
    xw = pb.whiten(pb.lift(locked_lag_columns(ctx)))
    z = stats.project_out(U_others, xw)[:, 0]
    zz = float(z @ z)
    if zz <= 0.0:
        return LagCheck(0.0, 0, float("nan"), float("nan"))
    tau_min = float(z @ e_others) / zz
    e_lag = e_others - tau_min * z
    dof_res = max(e_lag.size - U_others.shape[1] - 1, 1)
    tau_sd_min = float(np.sqrt(float(e_lag @ e_lag) / dof_res / zz))
    U = stats.orthonormal_basis(np.hstack([U_others, z[:, None] / np.sqrt(zz)]))
    free = pb.whiten(pb.lift(per_axis(ctx, reading_rate_c_per_min(ctx))))
    with np.errstate(divide="ignore", invalid="ignore"):
        lp, _, k, _, _ = stats.linear_stats(U, free, e_lag, e_lag[:, None])
    return LagCheck(float(lp), int(k), 60.0 * tau_min, 60.0 * tau_sd_min)


def lag_alike(pb: Any, terms: list, f: Any, alpha: float, not_ident: dict[str, dict[str, str]],
              notes: list[str], design: Callable[..., tuple[np.ndarray, np.ndarray]]) -> Any:
    """A ``temperature_rate`` finding named only if its gains are not a lag's (issue 22).

    ``terms`` the accepted terms (``effect_id``, ``X``, ``rows``), ``design(pb, terms)`` the
    whitened design and data. When the free per-axis gains add nothing beyond the locked
    lag (p > α), the finding is reported ``not_identifiable`` with both candidates and the
    lag's τ; the rate term stays in the model (either removes the structure).
    """
    if f.effect != "temperature_rate" or f.rows:
        return f
    from calibration.discrepancy import stats

    others = [t for t in terms if t.effect_id != "temperature_rate"]
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in others) + 1
    if 8 * pb.m * p > stats.TALL_BYTES or pb.m <= p + 10:
        notes.append("temperature_rate: not checked against a lagging temperature channel "
                     "(gains locked to ∂output/∂T): the recording is too long for that design")
        return f
    Xw, yw = design(pb, others)
    U = stats.orthonormal_basis(Xw)
    del Xw
    check = lag_check(pb, U, yw - U @ (U.T @ yw))
    if check.dof == 0 or check.log_p_free <= np.log(alpha) or not np.isfinite(check.tau_s):
        return f
    if check.tau_s + 2.0 * check.tau_sd_s < 0.0:  # a channel cannot lead the die
        return f
    lag = (f"a temperature channel (or die) lagging by τ ≈ {check.tau_s:.0f} s (± "
           f"{check.tau_sd_s:.0f} s from noise alone)")
    why = (f"its per-axis gains are those of a lag, locked to the model's own ∂output/∂T "
           f"(the free gains add nothing beyond one τ: p = {np.exp(check.log_p_free):.2g} > "
           f"α, {check.dof} dof): a recorded temperature that lags the die by τ makes "
           "exactly that rate term")
    not_ident.setdefault("temperature_rate", {
        "effect": "temperature_rate", "why": f"not separable from {lag}: {why}",
        "experiment": LAG_EXPERIMENT})
    return replace(
        f, effect="not_identifiable", where={**f.where, "candidates": ["temperature_rate", lag],
                                             "lag_tau_s": check.tau_s,
                                             "lag_tau_sd_s": check.tau_sd_s},
        explanation=(f"Structure beyond noise that temperature_rate or {lag} explain alike: "
                     f"{why}. It is modelled (with the temperature_rate term) but not named; "
                     f"to separate them: {LAG_EXPERIMENT}."),
        parameters={}, parameter_sd={}, confusers=[])


# --- one gain on every plateau (issue 22) -------------------------------------------------
MIN_PLATEAUS_GAIN = 3  # two plateaus' gains are one contrast: the common gain and one more


def gain_differs_between_plateaus(pb: Any, U: np.ndarray, e: np.ndarray, axes: list[str],
                                  alpha: float) -> dict[str, Any] | None:
    """The place where the rate term's gain differs between plateaus beyond noise, or None.

    The physics (effects.md): the output moves by ``k·dT/dt`` with one gain per axis for the
    whole recording; the die's rate on every plateau where it is still settling predicts the
    output there. ``U``, ``e``: the model with the rate term. A gain free per plateau (the
    rate column of each plateau on its own, per axis) is tested after it (F, at α): under the
    effect it is noise. Structure in time confined to some plateaus (a fixture settling after
    the moves of one plateau, a chamber cycle in phase with a few plateaus' warm-ups) takes
    the common gain only where it happens to look like the die's settling and leaves the
    per-plateau gains apart.
    """
    from calibration.discrepancy.context import AXES
    from calibration.discrepancy.effects.structure import fitted_after, log_p, whitened

    ctx = pb.ctx
    rate = reading_rate_c_per_min(ctx)
    ax = tuple(AXES.index(a) for a in axes if a in AXES) or (0, 1, 2)
    steps = [int(s) for s in ctx.step_ids if np.any(np.abs(rate[ctx.steps == s]) > 0)]
    if len(steps) < MIN_PLATEAUS_GAIN:
        return None
    cols = np.zeros((ctx.n, 3, len(steps) * len(ax)))
    for i, s in enumerate(steps):
        on = ctx.steps == s
        for j, a in enumerate(ax):
            cols[on, a, i * len(ax) + j] = rate[on]
    Xw = whitened(pb, cols)
    lp, k = log_p(U, e, Xw)
    if k == 0 or lp > np.log(alpha):
        return None
    # Where: the plateaus whose own gain departs by at least half the largest departure.
    fit = fitted_after(U, e, Xw)
    on = ctx.steps[pb.row]
    per_step = np.array([np.sqrt(np.mean(fit[on == s] ** 2)) for s in steps])
    big = [s for s, v in zip(steps, per_step, strict=True) if v >= 0.5 * per_step.max()]
    rows = np.isin(ctx.steps, big)
    return {"kind": "time", "steps": big,
            "positions": sorted({int(p) for p in ctx.positions[rows]}),
            "time_s": [float(ctx.t_s[rows].min()), float(ctx.t_s[rows].max())],
            "axes": [AXES[a] for a in ax], "log10_p": round(float(lp / np.log(10)), 1),
            "why": ("temperature_rate is one gain per axis on every plateau, but the gain "
                    "fitted plateau by plateau differs beyond noise (the structure follows "
                    "the die's rate on some plateaus only: something else in time)")}
