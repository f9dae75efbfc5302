"""Stability decisions for a soak step: pure functions, no I/O, no clock.

No chamber controller reports "stable", so the engine decides from two sources:

* the chamber: its process value (PV, air) has stayed within ``tol_c`` of the
  target while the working setpoint equals the target, for a dwell
  (:func:`chamber_settled`);
* the sensor die, through the sensor's own temperature channel: a first-order
  approach T(t) = T∞ − (T∞ − T0)·e^(−t/τ) is fitted to the recent history
  (:func:`fit_approach`, with its covariance) and extrapolated over the coming
  position sweep.

What the soak has to achieve follows from how the data are used: every
position row carries its measured die temperature and the thermal fit
conditions it per step with a straight line in time (``calibration.
temperature_conditioning``). A die still approaching its final value during
the sweep therefore costs accuracy only through

1. the *curvature* of the approach over the sweep, which the per-step line
   cannot follow (the residual of e^(−u/τ) about its best line), and
2. the *rate*: while the die moves, package and board lag it by about
   ``gradient_lag_s``; the stress state the output depends on belongs to a
   temperature ``gradient_lag_s × dT/dt`` behind the reading.

Both are temperature errors; times the sensor's temperature coefficient they
become output errors, compared with the noise the campaign has anyway
(:func:`temperature_budget_c`: a fraction of one reading's noise over the
tempco). The part that varies from position to position (curvature, change of
the rate lag) is compared with one reading's noise, ``temp_budget_c``; the
part common to the whole sweep (the rate lag, taken at the die's rate *now*:
a slower time constant the history cannot reveal yet would keep it up) shifts
the step's temperature, is not averaged over the positions, and is compared
with the noise of the step mean, ``temp_budget_c / √n_positions``. The step is soaked
when the upper confidence bounds of both (:func:`sweep_error_c`, fit
covariance by the delta method) are within them. Every position must also be
within ``step_tol_c`` of the final value (the steps stay where the plan put
them), and at the coldest and hottest step the sweep-mean offset within
``edge_tol_c``: those steps set the model's valid range.

The die reading may carry a constant offset, so only its *approach* is used,
never its absolute value against the setpoint.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

# The soak decision's defaults are the campaign spec's (written once there, with why).
from calibration.campaign_spec import (
    DEFAULT_DRIFT_BUDGET,
    DEFAULT_EDGE_TOL_C,
    DEFAULT_GRADIENT_LAG_S,
    DEFAULT_STEP_TOL_C,
    DEFAULT_TEMPCO_UG_PER_C,
)

POLICIES = ("predictive", "dwell", "fixed")

SWEEP_POINTS = 25  # samples of the sweep used to evaluate its error (~ one per position)


def temperature_budget_c(reading_noise_g: float, tempco_ug_per_c: float = DEFAULT_TEMPCO_UG_PER_C,
                         fraction: float = DEFAULT_DRIFT_BUDGET) -> float:
    """rms die-temperature error (°C) whose output effect is ``fraction`` of the reading noise.

    ``reading_noise_g`` is the per-axis noise of one averaged position reading
    (raw sample sd / √samples); ``tempco_ug_per_c`` the output change per °C.
    """
    return fraction * reading_noise_g * 1e6 / tempco_ug_per_c


def lag_from_rate_gain_s(rate_gain_ug_per_c_per_min: float, tempco_ug_per_c: float) -> float:
    """The package lag (s) whose rate error equals a ``temperature_rate`` gain k.

    k × dT/dt (µg, rate in °C/min) = tempco × lag × dT/dt (rate in °C/s):
    lag = 60 · k / tempco. k = 100 µg per °C/min at 150 µg/°C → 40 s.
    """
    if not (rate_gain_ug_per_c_per_min >= 0 and tempco_ug_per_c > 0):
        raise ValueError(f"rate gain must be >= 0 and tempco > 0, got "
                         f"{rate_gain_ug_per_c_per_min} and {tempco_ug_per_c}")
    return 60.0 * rate_gain_ug_per_c_per_min / tempco_ug_per_c


@dataclass(frozen=True)
class StabilityConfig:
    """How a soak is judged. Times in s, temperatures in °C."""

    policy: str = "predictive"  # predictive | dwell | fixed (the seed: exactly soak_min)
    soak_s: float = 3600.0  # the nominal soak (seed: ~1 h); fixed policy waits exactly this
    min_soak_s: float = 600.0  # never declare stable earlier than this after the soak starts
    max_soak_s: float = 7200.0  # after this the step is marked max_soak_reached
    tol_c: float = 0.3  # chamber PV band around the target
    dwell_s: float = 300.0  # PV continuously in band at least this long
    # rms temperature error the thermal model may see during the sweep (spec.py derives it)
    temp_budget_c: float = temperature_budget_c(2.5e-4 / math.sqrt(200))
    gradient_lag_s: float = DEFAULT_GRADIENT_LAG_S  # package/board lag behind the die reading
    # output change per °C of die temperature: converts a measured rate gain into a lag
    tempco_ug_per_c: float = DEFAULT_TEMPCO_UG_PER_C
    sweep_s: float = 360.0  # expected duration of the step's position sweep (runner passes it)
    n_positions: int = 24  # positions per step (runner passes it): a step mean's noise is σ/√n
    step_tol_c: float = DEFAULT_STEP_TOL_C  # every step: |T − T∞| at the sweep start
    edge_tol_c: float = DEFAULT_EDGE_TOL_C  # extreme steps: sweep-mean offset from final
    die_tol_c: float | None = None  # optional classic rule: |T(now) − T∞| below this as well
    confidence_z: float = 2.0  # decisions use estimate + z·σ (fit covariance, delta method)
    max_resid_c: float = 0.15  # rms residual above this: the curve is not a first-order approach
    min_durbin_watson: float = 1.0  # smoother residuals: a second time constant is still visible
    min_points: int = 6  # sensor history points needed before a prediction is trusted
    window_s: float = 1800.0  # fit only the recent history: early soak is a two-stage lag
    rate_window_s: float = 600.0  # the fit must match the die's measured rate over this much

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise ValueError(f"stability policy must be one of {POLICIES}, got {self.policy!r}")
        if not self.temp_budget_c > 0:
            raise ValueError(f"temp_budget_c must be positive, got {self.temp_budget_c}")


@dataclass(frozen=True)
class ApproachFit:
    """Result of fitting T(t) = T∞ − a·e^(−(t − t_first)/τ) to a history."""

    t_inf_c: float
    t0_c: float
    tau_s: float
    tau_sd_s: float  # 1-σ uncertainty of τ (inf when not determined)
    resid_rms_c: float
    n: int
    ok: bool  # the optimiser converged and τ is finite and positive
    cov: np.ndarray | None = field(default=None, compare=False, repr=False)  # of (T∞, a, τ)
    durbin_watson: float = 2.0  # of the residuals in time order (≈ 2 for white noise)
    resid_c: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def amplitude_c(self) -> float:
        return self.t_inf_c - self.t0_c

    def offset_c(self, t_rel_s: float) -> float:
        """Signed T∞ − T(t) at ``t_rel_s`` seconds after the first history point."""
        return self.amplitude_c * math.exp(-t_rel_s / self.tau_s)

    def predicted_offset_c(self, t_rel_s: float) -> float:
        """|T(t) − T∞| at ``t_rel_s`` seconds after the first history point."""
        return abs(self.offset_c(t_rel_s))


@dataclass(frozen=True)
class Decision:
    stable: bool
    reason: str  # human sentence-ish tag recorded in steps_log
    tau_s: float | None = None
    predicted_offset_c: float | None = None  # |T∞ − T(now)|, point estimate
    predicted_error_c: float | None = None  # upper bound of the sweep's error, as °C per reading
    die_rate_c_per_min: float | None = None  # dT/dt of the die now (fit or trend)
    max_soak_reached: bool = False
    # Not yet stable: the predicted wait (s) until it may be (the binding bound decaying as
    # e^(−Δt/τ), or the minimum soak's end). None: unknown, poll at the usual period. The
    # runner polls then instead of a whole period later (``next_poll_s``).
    ready_in_s: float | None = None


def next_poll_s(decision: Decision, poll_s: float, min_poll_s: float) -> float:
    """When to look again after ``decision``: the usual ``poll_s``, or sooner when the
    decision predicts it may be stable sooner (never sooner than ``min_poll_s``).

    Why: a soak ends at a poll, so with a fixed period it overshoots the moment the die
    meets its budgets by half a period on average (≈ 30 s per step at 60 s); the fit
    already says when that moment comes.
    """
    if decision.stable or decision.ready_in_s is None or not math.isfinite(decision.ready_in_s):
        return poll_s
    return float(min(poll_s, max(min_poll_s, decision.ready_in_s)))


def chamber_settled(
    t_s: np.ndarray, pv_c: np.ndarray, wsp_c: np.ndarray, target_c: float, tol_c: float,
    dwell_s: float,
) -> bool:
    """PV within ``tol_c`` of the target, and WSP == target, for the last ``dwell_s`` s.

    Samples are the chamber polls of the soak so far (time ordered). The band
    must hold continuously over a window that spans at least ``dwell_s``.
    """
    t_s, pv_c, wsp_c = (np.asarray(a, float) for a in (t_s, pv_c, wsp_c))
    if t_s.size == 0:
        return False
    ok = (np.abs(pv_c - target_c) <= tol_c) & (np.abs(wsp_c - target_c) <= 1e-6 + 1e-3)
    if not ok[-1]:
        return False
    bad = np.flatnonzero(~ok)
    first_good = int(bad[-1]) + 1 if bad.size else 0
    return bool(t_s[-1] - t_s[first_good] >= dwell_s)


def sweep_error_c(offset_c: float, tau_s: float, sweep_s: float,
                  gradient_lag_s: float) -> tuple[float, float, float]:
    """Temperature errors of a sweep that starts ``offset_c`` (= T∞ − T) from the final value.

    The die follows T(u) = T∞ − offset·e^(−u/τ) over the sweep u ∈ [0, sweep_s].
    The thermal fit sees the straight line through the readings; the output
    follows T − gradient_lag_s·dT/du. Their difference has a part that varies
    over the sweep and a mean. Returns

    * the rms of the varying part (curvature the line cannot follow, and the
      change of the rate lag): it differs from position to position, like noise;
    * |mean| (the rate lag averaged over the sweep): common to every position
      of the step, so it is not averaged away and shifts the step's temperature;
    * the mean |T − T∞| over the sweep (how far the step's mean temperature is
      from the final one).
    """
    if not (math.isfinite(offset_c) and math.isfinite(tau_s) and tau_s > 0):
        return math.inf, math.inf, math.inf
    u = np.linspace(0.0, max(sweep_s, 0.0), SWEEP_POINTS)
    e = np.exp(-u / tau_s)
    temp = -offset_c * e  # relative to T∞
    if sweep_s > 0:
        basis = np.column_stack([np.ones_like(u), u / sweep_s])
        coef, *_ = np.linalg.lstsq(basis, temp, rcond=None)
        resid = temp - basis @ coef
    else:
        resid = np.zeros_like(u)
    err = resid - gradient_lag_s * (offset_c / tau_s) * e
    common = float(np.mean(err))
    return (float(np.sqrt(np.mean((err - common) ** 2))), abs(common),
            float(np.mean(np.abs(temp))))


def fit_approach(t_s: np.ndarray, temp_c: np.ndarray) -> ApproachFit:
    """Fit a first-order exponential approach to a temperature history.

    τ is scanned on a log grid (the model is linear in T∞ and the amplitude for
    a fixed τ), then refined by Gauss–Newton, which also gives the covariance
    of (T∞, a, τ). A flat or linear history gives a huge τ with a huge
    uncertainty: not credible, which is what it should be.
    """
    t = np.asarray(t_s, float)
    y = np.asarray(temp_c, float)
    n = t.size
    if n < 4:
        return ApproachFit(float(y[-1]) if n else math.nan, math.nan, math.nan, math.inf,
                           math.inf, n, False)
    x = t - t[0]
    span_s = max(float(x[-1]), 1.0)
    # Vectorised grid: for each τ, closed-form least squares of y = T∞ − a·e^(−x/τ).
    taus = np.geomspace(span_s / 30.0, span_s * 20.0, 40)
    E = np.exp(-x[None, :] / taus[:, None])  # (k, n)
    e_mean, y_mean = E.mean(axis=1), y.mean()
    cov_ey = (E * y[None, :]).mean(axis=1) - e_mean * y_mean
    var_e = np.maximum((E * E).mean(axis=1) - e_mean**2, 1e-300)
    slope = cov_ey / var_e  # dy/de = −a
    sse = np.sum((y[None, :] - (y_mean + slope[:, None] * (E - e_mean[:, None]))) ** 2, axis=1)
    i = int(np.argmin(sse))
    tau0, amp0 = float(taus[i]), float(-slope[i])
    tinf0 = float(y_mean - slope[i] * e_mean[i])
    p, cov = _gauss_newton(x, y, np.array([tinf0, amp0, tau0]))
    t_inf, amp, tau = (float(v) for v in p)
    resid = y - (t_inf - amp * np.exp(-x / max(tau, 1e-9)))
    ok = bool(math.isfinite(tau) and tau > 0)
    ss = float(np.sum(resid**2))
    dw = float(np.sum(np.diff(resid) ** 2) / ss) if ss > 0 else 2.0
    tau_sd = math.sqrt(cov[2, 2]) if cov is not None and cov[2, 2] >= 0 else math.inf
    return ApproachFit(
        t_inf_c=t_inf, t0_c=t_inf - amp, tau_s=tau, tau_sd_s=tau_sd,
        resid_rms_c=float(np.sqrt(np.mean(resid**2))), n=n, ok=ok, cov=cov, durbin_watson=dw,
        resid_c=resid,
    )


def _gauss_newton(x: np.ndarray, y: np.ndarray, p: np.ndarray,
                  iterations: int = 8) -> tuple[np.ndarray, np.ndarray | None]:
    """Refine (T∞, a, τ) from the grid optimum; return it and its covariance (None if singular).

    Hand-rolled (3 parameters, analytic Jacobian) because ``curve_fit`` costs
    ~10 ms per call and the soak loop calls this every poll.
    """
    def jac(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        e = np.exp(-x / q[2])
        r = y - (q[0] - q[1] * e)
        J = np.column_stack([np.ones_like(x), -e, -q[1] * e * x / q[2] ** 2])
        return r, J

    for _ in range(iterations):
        r, J = jac(p)
        try:
            dp, *_ = np.linalg.lstsq(J, r, rcond=None)
        except np.linalg.LinAlgError:
            break
        q = p + dp
        if not (np.all(np.isfinite(q)) and q[2] > 0):
            break
        if np.sum(jac(q)[0] ** 2) > np.sum(r**2):
            break  # no longer improving: keep p
        p = q
    r, J = jac(p)
    dof = max(1, x.size - 3)
    try:
        cov = np.linalg.inv(J.T @ J) * float(np.sum(r**2)) / dof
    except np.linalg.LinAlgError:
        return p, None
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) < 0):
        return p, None
    return p, cov


def decide(
    cfg: StabilityConfig,
    elapsed_s: float,
    chamber_ok: bool,
    sensor_t_s: np.ndarray,
    sensor_c: np.ndarray,
    *,
    sweep_s: float | None = None,
    n_positions: int | None = None,
    edge: bool = False,
    rate_gain_ug_per_c_per_min: float | None = None,
    order_repeats: int = 1,
) -> Decision:
    """Is the step soaked, ``elapsed_s`` after the soak started?

    ``chamber_ok`` is :func:`chamber_settled` for the soak's chamber polls;
    ``sensor_t_s``/``sensor_c`` the die temperature history since the soak start;
    ``sweep_s`` how long the step's positions will take (default ``cfg.sweep_s``);
    ``n_positions`` how many positions a step has (default ``cfg.n_positions``);
    ``edge`` whether this is the coldest or hottest step of the campaign;
    ``rate_gain_ug_per_c_per_min`` the sensor's measured sensitivity to the rate
    of die-temperature change k (upper bound, µg per °C/min, e.g. from
    :func:`service.engine.rate_gain.rate_gain_for_decision`): the rate lag is then
    60·k / ``tempco_ug_per_c`` s instead of the assumed ``gradient_lag_s``
    (None, the default, keeps the assumption);
    ``order_repeats`` how many steps visit the positions in this step's order: the varying
    part of the sweep's error depends on the slot in the sweep, so it then meets the same
    position at every such step and is not averaged over them; its budget becomes
    ``temp_budget_c / √order_repeats``, the noise of a position's mean over those steps.
    """
    if rate_gain_ug_per_c_per_min is not None:
        cfg = dataclasses.replace(cfg, gradient_lag_s=lag_from_rate_gain_s(
            rate_gain_ug_per_c_per_min, cfg.tempco_ug_per_c))
    if cfg.policy == "fixed":
        if elapsed_s >= cfg.soak_s:
            return Decision(True, "fixed_soak_elapsed")
        return Decision(False, "fixed_soak_waiting")
    if elapsed_s >= cfg.max_soak_s:
        return Decision(True, "max_soak_reached", max_soak_reached=True)
    if not chamber_ok:
        return Decision(False, "chamber_not_settled")
    if cfg.policy == "dwell":
        if elapsed_s >= cfg.soak_s:
            return Decision(True, "chamber_dwell_and_soak")
        return Decision(False, "dwell_waiting")
    if elapsed_s < cfg.min_soak_s:
        return Decision(False, "min_soak_waiting", ready_in_s=cfg.min_soak_s - elapsed_s)
    return _predict(cfg, np.asarray(sensor_t_s, float), np.asarray(sensor_c, float),
                    cfg.sweep_s if sweep_s is None else float(sweep_s),
                    cfg.n_positions if n_positions is None else int(n_positions), edge,
                    cfg.temp_budget_c / math.sqrt(max(order_repeats, 1)))


def _predict(cfg: StabilityConfig, t_s: np.ndarray, temp_c: np.ndarray, sweep_s: float,
             n_positions: int, edge: bool, varying_budget_c: float) -> Decision:
    """The die-temperature half of :func:`decide` (policy ``predictive``);
    ``varying_budget_c``: ``temp_budget_c`` over √(steps visiting in this order)."""
    recent = t_s >= t_s[-1] - cfg.window_s if t_s.size else t_s.astype(bool)
    t_s, temp_c = t_s[recent], temp_c[recent]
    if t_s.size < cfg.min_points:
        return Decision(False, "too_few_sensor_points")
    flat = _flat(cfg, t_s, temp_c, sweep_s, n_positions, varying_budget_c)
    if flat is not None:
        return flat
    fit = fit_approach(t_s, temp_c)
    if not fit.ok or fit.cov is None:
        return Decision(False, "fit_failed")
    span_s = float(t_s[-1] - t_s[0])
    offset_c = fit.offset_c(span_s)
    rate = 60.0 * offset_c / fit.tau_s
    info = {"tau_s": fit.tau_s, "predicted_offset_c": abs(offset_c), "die_rate_c_per_min": rate}
    credible = (
        fit.resid_rms_c <= cfg.max_resid_c
        # τ longer than the history × 3 is an extrapolation, not a measurement
        and fit.tau_s <= 3.0 * span_s
        # smooth residuals: not (yet) a single time constant, e.g. a fixture lag still showing
        and (fit.n < 10 or fit.durbin_watson >= cfg.min_durbin_watson)
        and not _rate_mismatch(cfg, t_s, fit)
    )
    if not credible:
        return Decision(False, "fit_not_credible", **info)

    def bounds(p: np.ndarray) -> np.ndarray:
        off = p[1] * math.exp(-span_s / p[2]) if p[2] > 0 else math.inf
        varying, _, mean_off = sweep_error_c(off, p[2], sweep_s, cfg.gradient_lag_s)
        # The common part with the rate of *now*, not decaying over the sweep: a slower
        # second time constant the history cannot reveal yet would keep the rate up.
        common = cfg.gradient_lag_s * abs(off) / p[2]
        return np.array([varying, common, mean_off, abs(off)])

    p = np.array([fit.t_inf_c, fit.amplitude_c, fit.tau_s])
    upper = _upper_bounds(bounds, p, fit.cov, cfg.confidence_z)
    varying_hi, common_hi, mean_off_hi, off_hi = (float(v) for v in upper)
    common_budget_c = cfg.temp_budget_c / math.sqrt(max(n_positions, 1))
    info["predicted_error_c"] = max(varying_hi, common_hi * math.sqrt(max(n_positions, 1)))
    ok = (varying_hi <= varying_budget_c and common_hi <= common_budget_c
          and off_hi <= cfg.step_tol_c)
    if edge:
        ok = ok and mean_off_hi <= cfg.edge_tol_c
    if cfg.die_tol_c is not None:
        ok = ok and off_hi < cfg.die_tol_c
    if ok:
        return Decision(True, "die_predicted_within_tol", **info)
    # Every bound above is proportional to the die's offset, which decays as e^(−Δt/τ): the
    # budget binding hardest is met after τ·ln(bound / budget). Approximate (the bounds' σ
    # part does not decay exactly so), which is why the runner still re-decides then.
    ratios = [varying_hi / varying_budget_c, common_hi / common_budget_c,
              off_hi / cfg.step_tol_c]
    if edge:
        ratios.append(mean_off_hi / cfg.edge_tol_c)
    if cfg.die_tol_c is not None:
        ratios.append(off_hi / cfg.die_tol_c)
    worst = max(ratios)
    ready_in_s = fit.tau_s * math.log(worst) if math.isfinite(worst) and worst > 1.0 else None
    return Decision(False, "die_approaching", ready_in_s=ready_in_s, **info)


def _rate_mismatch(cfg: StabilityConfig, t_s: np.ndarray, fit: ApproachFit) -> bool:
    """Do the residuals of the last ``rate_window_s`` have a significant slope?

    Then the die's measured rate differs from the fit's: typically a slow second
    time constant whose curvature is still below the noise but whose rate is
    not, and which the first-order prediction would miss.
    """
    if fit.resid_c is None:
        return False
    last = t_s >= t_s[-1] - cfg.rate_window_s
    if int(last.sum()) < 5:
        return False
    x, r = t_s[last] - t_s[last][0], fit.resid_c[last]
    sxx = float(np.sum((x - x.mean()) ** 2))
    slope, intercept = np.polyfit(x, r, 1)
    s2 = float(np.sum((r - slope * x - intercept) ** 2)) / max(1, x.size - 2)
    return bool(abs(float(slope)) > cfg.confidence_z * math.sqrt(s2 / sxx))


def _upper_bounds(f, p: np.ndarray, cov: np.ndarray, z: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    """f(p) + z·σ for each output of ``f``, σ by the delta method with covariance ``cov``."""
    f0 = f(p)
    if not np.all(np.isfinite(f0)):
        return np.full_like(f0, math.inf)
    grads = np.zeros((f0.size, p.size))
    for j in range(p.size):
        h = 1e-6 * max(abs(p[j]), 1e-3)
        q = p.copy()
        q[j] += h
        grads[:, j] = (f(q) - f0) / h
    var = np.einsum("ij,jk,ik->i", grads, cov, grads)
    sd = np.sqrt(np.where(np.isfinite(var) & (var >= 0), var, math.inf))
    return f0 + z * sd


def _flat(cfg: StabilityConfig, t_s: np.ndarray, temp_c: np.ndarray, sweep_s: float,
          n_positions: int, varying_budget_c: float) -> Decision | None:
    """Stable if even the upper bound of the linear trend keeps the die within the budgets
    (an exponential fit to pure noise is ill-posed); else None.

    The whole drift over the sweep must fit the per-reading budget (whatever its
    shape, the line could absorb none of it), and its rate lag the step-mean budget.
    """
    x = t_s - t_s[0]
    n = x.size
    sxx = float(np.sum((x - x.mean()) ** 2))
    if n < 3 or sxx <= 0:
        return None
    slope, intercept = np.polyfit(x, temp_c, 1)
    resid = temp_c - (slope * x + intercept)
    s2 = float(np.sum(resid**2)) / (n - 2)
    slope_hi = abs(float(slope)) + cfg.confidence_z * math.sqrt(s2 / sxx)
    drift_c = slope_hi * sweep_s
    lag_c = slope_hi * cfg.gradient_lag_s
    if (drift_c <= varying_budget_c
            and lag_c <= cfg.temp_budget_c / math.sqrt(max(n_positions, 1))
            and math.sqrt(s2) <= cfg.max_resid_c):
        return Decision(True, "die_flat", predicted_offset_c=drift_c,
                        predicted_error_c=max(drift_c, lag_c * math.sqrt(max(n_positions, 1))),
                        die_rate_c_per_min=60.0 * float(slope))
    return None
