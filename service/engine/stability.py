"""Stability decisions for a soak step: pure functions, no I/O, no clock.

No chamber controller reports "stable", so the engine decides from two sources:

* the chamber: its process value (PV, air) has stayed within ``tol_c`` of the
  target while the working setpoint equals the target, for a dwell
  (:func:`chamber_settled`);
* the sensor die, through the sensor's own temperature channel: a first-order
  exponential approach T(t) = T∞ − (T∞ − T0)·e^(−t/τ) is fitted to the recent
  history (:func:`fit_approach`) and the step is declared stable once the
  predicted residual |T(now) − T∞| is below ``die_tol_c`` and the fit is
  credible (:func:`decide`).

The die reading may carry a constant offset, so only its *approach* is used,
never its absolute value against the setpoint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

POLICIES = ("predictive", "dwell", "fixed")


@dataclass(frozen=True)
class StabilityConfig:
    """How a soak is judged. Times in s, temperatures in °C."""

    policy: str = "predictive"  # predictive | dwell | fixed (the seed: exactly soak_min)
    soak_s: float = 3600.0  # the nominal soak (seed: ~1 h); fixed policy waits exactly this
    min_soak_s: float = 600.0  # never declare stable earlier than this after the soak starts
    max_soak_s: float = 7200.0  # after this the step is marked max_soak_reached
    tol_c: float = 0.3  # chamber PV band around the target
    dwell_s: float = 300.0  # PV continuously in band at least this long
    die_tol_c: float = 0.1  # predicted die residual offset that counts as soaked
    max_tau_rel_sd: float = 0.35  # a fit whose τ is less certain than this is not credible
    max_resid_c: float = 0.15  # rms residual above this: the curve is not a first-order approach
    min_points: int = 6  # sensor history points needed before a prediction is trusted
    window_s: float = 1800.0  # fit only the recent history: early soak is a two-stage lag
    flat_span_c: float = 0.05  # history flatter than this (max−min of a trend) is already soaked

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise ValueError(f"stability policy must be one of {POLICIES}, got {self.policy!r}")


@dataclass(frozen=True)
class ApproachFit:
    """Result of fitting T(t) = T∞ − (T∞ − T0)·e^(−(t − t_first)/τ) to a history."""

    t_inf_c: float
    t0_c: float
    tau_s: float
    tau_sd_s: float  # 1-σ uncertainty of τ (inf when not determined)
    resid_rms_c: float
    n: int
    ok: bool  # the optimiser converged and τ is finite and positive

    def predicted_offset_c(self, t_rel_s: float) -> float:
        """|T(t) − T∞| at ``t_rel_s`` seconds after the first history point."""
        return abs(self.t_inf_c - self.t0_c) * math.exp(-t_rel_s / self.tau_s)


@dataclass(frozen=True)
class Decision:
    stable: bool
    reason: str  # human sentence-ish tag recorded in steps_log
    tau_s: float | None = None
    predicted_offset_c: float | None = None
    max_soak_reached: bool = False


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


def fit_approach(t_s: np.ndarray, temp_c: np.ndarray) -> ApproachFit:
    """Fit a first-order exponential approach to a temperature history.

    τ is scanned on a log grid (the model is linear in T∞ and the amplitude for
    a fixed τ), then refined with ``curve_fit`` for its covariance. A flat or
    linear history gives a huge τ with a huge uncertainty: not credible, which
    is what it should be.
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
    p, tau_sd = _gauss_newton(x, y, np.array([tinf0, amp0, tau0]))
    t_inf, amp, tau = (float(v) for v in p)
    resid = y - (t_inf - amp * np.exp(-x / max(tau, 1e-9)))
    ok = bool(math.isfinite(tau) and tau > 0)
    return ApproachFit(
        t_inf_c=t_inf, t0_c=t_inf - amp, tau_s=tau, tau_sd_s=tau_sd,
        resid_rms_c=float(np.sqrt(np.mean(resid**2))), n=n, ok=ok,
    )


def _gauss_newton(x: np.ndarray, y: np.ndarray, p: np.ndarray,
                  iterations: int = 8) -> tuple[np.ndarray, float]:
    """Refine (T∞, a, τ) from the grid optimum; return it and the 1-σ of τ.

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
        tau_sd = math.sqrt(cov[2, 2]) if cov[2, 2] >= 0 else math.inf
    except np.linalg.LinAlgError:
        tau_sd = math.inf
    return p, tau_sd


def decide(
    cfg: StabilityConfig,
    elapsed_s: float,
    chamber_ok: bool,
    sensor_t_s: np.ndarray,
    sensor_c: np.ndarray,
) -> Decision:
    """Is the step soaked, ``elapsed_s`` after the soak started?

    ``chamber_ok`` is :func:`chamber_settled` for the soak's chamber polls;
    ``sensor_t_s``/``sensor_c`` the die temperature history since the soak start.
    """
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
        return Decision(False, "min_soak_waiting")
    return _predict(cfg, np.asarray(sensor_t_s, float), np.asarray(sensor_c, float))


def _predict(cfg: StabilityConfig, t_s: np.ndarray, temp_c: np.ndarray) -> Decision:
    """The die-temperature half of :func:`decide` (policy ``predictive``)."""
    recent = t_s >= t_s[-1] - cfg.window_s if t_s.size else t_s.astype(bool)
    t_s, temp_c = t_s[recent], temp_c[recent]
    if t_s.size < cfg.min_points:
        return Decision(False, "too_few_sensor_points")
    # A history whose linear trend moves less than flat_span_c is soaked whatever τ is:
    # an exponential fit to pure noise is ill-posed and would never be "credible".
    slope, intercept = np.polyfit(t_s - t_s[0], temp_c, 1)
    trend_span_c = abs(float(slope) * float(t_s[-1] - t_s[0]))
    resid_lin = temp_c - (slope * (t_s - t_s[0]) + intercept)
    if trend_span_c < cfg.flat_span_c and float(np.std(resid_lin)) < cfg.max_resid_c:
        return Decision(True, "die_flat", predicted_offset_c=trend_span_c)
    fit = fit_approach(t_s, temp_c)
    if not fit.ok:
        return Decision(False, "fit_failed")
    offset_c = fit.predicted_offset_c(float(t_s[-1] - t_s[0]))
    credible = (
        fit.tau_sd_s / fit.tau_s <= cfg.max_tau_rel_sd
        and fit.resid_rms_c <= cfg.max_resid_c
        # τ longer than the history × 3 is an extrapolation, not a measurement
        and fit.tau_s <= 3.0 * float(t_s[-1] - t_s[0])
    )
    if not credible:
        return Decision(False, "fit_not_credible", tau_s=fit.tau_s, predicted_offset_c=offset_c)
    if offset_c < cfg.die_tol_c:
        return Decision(True, "die_predicted_within_tol", tau_s=fit.tau_s,
                        predicted_offset_c=offset_c)
    return Decision(False, "die_approaching", tau_s=fit.tau_s, predicted_offset_c=offset_c)
