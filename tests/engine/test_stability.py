"""Stability decisions on synthetic die-temperature curves (pure functions).

The decisions are checked against the *true* curve: when the predictive policy
says "stable", the sweep that follows must really be within the temperature
budget (and within the step / edge tolerances), up to the probe noise.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from service.engine.rate_gain import (
    PRIOR_RATE_GAIN_UG_PER_C_PER_MIN,
    RateGain,
    SoakProbes,
    estimate_rate_gain,
    is_informative,
    rate_gain_for_decision,
)
from service.engine.stability import (
    Decision,
    StabilityConfig,
    chamber_settled,
    decide,
    fit_approach,
    lag_from_rate_gain_s,
    next_poll_s,
    sweep_error_c,
    temperature_budget_c,
)

CFG = StabilityConfig(soak_s=3600.0, min_soak_s=600.0, max_soak_s=7200.0)
# A sensor without rate sensitivity: only what the per-step line cannot follow counts.
NO_LAG = StabilityConfig(gradient_lag_s=0.0)
SWEEP_S = 360.0
PROBE_NOISE_C = 0.035  # 8-sample probe of a 0.1 °C channel


def approach(t_s: np.ndarray, t_inf: float, t0: float, tau_s: float, noise_c: float,
             seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return t_inf - (t_inf - t0) * np.exp(-t_s / tau_s) + rng.normal(0, noise_c, t_s.size)


def first_stable(cfg: StabilityConfig, t_s: np.ndarray, temp_c: np.ndarray,
                 **kw: object) -> tuple[float, object] | None:
    for k in range(2, t_s.size + 1):
        d = decide(cfg, float(t_s[k - 1]), True, t_s[:k], temp_c[:k], **kw)  # type: ignore[arg-type]
        if d.stable:
            return float(t_s[k - 1]), d
    return None


def true_sweep_errors_c(curve, t_start_s: float, sweep_s: float,  # type: ignore[no-untyped-def]
                        lag_s: float) -> tuple[float, float]:
    """(rms varying part, |mean|) of (T − lag·dT/dt) − the line through T, numerically."""
    u = np.linspace(t_start_s, t_start_s + sweep_s, 201)
    temp = curve(u)
    rate = np.gradient(temp, u)
    line = np.polyval(np.polyfit(u - t_start_s, temp, 1), u - t_start_s)
    err = temp - lag_s * rate - line
    return float(np.std(err)), abs(float(np.mean(err)))


def true_sweep_error_c(curve, t_start_s: float, sweep_s: float, lag_s: float) -> float:  # type: ignore[no-untyped-def]
    """Total rms of the same difference."""
    return float(np.hypot(*true_sweep_errors_c(curve, t_start_s, sweep_s, lag_s)))


def true_within_budgets(curve, t_start_s: float, slack: float = 1.2) -> bool:  # type: ignore[no-untyped-def]
    varying, common = true_sweep_errors_c(curve, t_start_s, SWEEP_S, CFG.gradient_lag_s)
    return (varying <= slack * CFG.temp_budget_c
            and common <= slack * CFG.temp_budget_c / math.sqrt(CFG.n_positions))


def test_fit_recovers_tau_final_value_and_covariance() -> None:
    t = np.arange(0.0, 2400.0, 60.0)
    fit = fit_approach(t, approach(t, 20.0, 5.0, 600.0, 0.02))
    assert fit.ok and fit.cov is not None and fit.cov.shape == (3, 3)
    assert fit.tau_s == pytest.approx(600.0, rel=0.05)
    assert fit.t_inf_c == pytest.approx(20.0, abs=0.05)
    assert fit.tau_sd_s < 0.1 * fit.tau_s
    assert 1.0 < fit.durbin_watson < 3.0  # white residuals


def test_budget_is_a_fraction_of_the_reading_noise_over_the_tempco() -> None:
    # ADXL355 protocol: 0.25 mg raw sample sd, 200 samples → 17.7 µg; tempco 150 µg/°C.
    budget = temperature_budget_c(2.5e-4 / math.sqrt(200), 150.0, 0.25)
    assert budget == pytest.approx(0.25 * 17.68 / 150.0, rel=1e-3)
    assert CFG.temp_budget_c == pytest.approx(budget)
    # A step mean of 24 readings is √24 less noisy: that is the budget of a common error.
    assert CFG.n_positions == 24
    # Noisier readings (fewer samples) tolerate a larger temperature error.
    assert temperature_budget_c(2.5e-4 / math.sqrt(20)) > budget


def test_sweep_error_is_what_a_straight_line_cannot_absorb() -> None:
    # A die already at its final value: nothing to absorb.
    assert sweep_error_c(0.0, 900.0, SWEEP_S, 10.0) == (0.0, 0.0, 0.0)
    # Without a gradient lag, a linear-looking (τ ≫ sweep) approach is absorbed by the line
    # and nothing is common to the sweep.
    varying, common, _ = sweep_error_c(1.0, 1e6, SWEEP_S, 0.0)
    assert varying < 1e-6 and common < 1e-12
    # The errors are proportional to the offset; the varying part grows with the sweep...
    v1, c1, m1 = sweep_error_c(1.0, 900.0, SWEEP_S, 10.0)
    v2, c2, m2 = sweep_error_c(2.0, 900.0, SWEEP_S, 10.0)
    assert (v2, c2, m2) == pytest.approx((2 * v1, 2 * c1, 2 * m1))
    assert sweep_error_c(1.0, 900.0, 2 * SWEEP_S, 10.0)[0] > v1
    # ...the common part is the rate lag, so it grows with the lag.
    assert sweep_error_c(1.0, 900.0, SWEEP_S, 40.0)[1] == pytest.approx(4 * c1)
    # Both agree with a brute-force evaluation on the true curve.
    def curve(t: np.ndarray) -> np.ndarray:
        return 20.0 - 1.0 * np.exp(-t / 900.0)

    assert np.hypot(v1, c1) == pytest.approx(true_sweep_error_c(curve, 0.0, SWEEP_S, 10.0),
                                             rel=0.05)
    # Mean offset over the sweep is below the offset at its start.
    assert 0.5 < m1 < 1.0


def within_budgets(offset_c: float, tau_s: float, cfg: StabilityConfig = CFG,
                   slack: float = 1.2) -> bool:
    varying, common, _ = sweep_error_c(offset_c, tau_s, SWEEP_S, cfg.gradient_lag_s)
    common = max(common, cfg.gradient_lag_s * offset_c / tau_s)  # the rate now, undecayed
    return (varying <= slack * cfg.temp_budget_c
            and common <= slack * cfg.temp_budget_c / math.sqrt(cfg.n_positions))


@pytest.mark.parametrize("tau_s", [300.0, 600.0, 900.0])
def test_declared_stable_only_when_the_sweep_is_within_budget(tau_s: float) -> None:
    t = np.arange(0.0, 7200.0, 60.0)
    y = approach(t, -30.0, -10.0, tau_s, PROBE_NOISE_C, seed=int(tau_s))
    found = first_stable(CFG, t, y, sweep_s=SWEEP_S)
    assert found is not None
    t_stable, d = found
    assert d.reason == "die_predicted_within_tol"  # type: ignore[attr-defined]
    offset = 20.0 * np.exp(-t_stable / tau_s)
    assert within_budgets(offset, tau_s)  # the decision was right (within the noise)
    assert offset <= CFG.step_tol_c
    # ...and not wastefully late: within 2 τ of the ideal moment (both budgets just met).
    v_unit, c_unit, _ = sweep_error_c(1.0, tau_s, SWEEP_S, CFG.gradient_lag_s)
    ideal_off = min(CFG.temp_budget_c / v_unit,
                    CFG.temp_budget_c / math.sqrt(CFG.n_positions) / c_unit, CFG.step_tol_c)
    ideal_s = tau_s * math.log(20.0 / ideal_off)
    assert t_stable <= max(ideal_s + 2 * tau_s, CFG.min_soak_s + 600)


def test_the_die_need_not_reach_the_final_value_only_the_budget() -> None:
    # The thermal model uses each row's die temperature: an interior step is soaked with
    # the die still well away from its final value, which a 0.1 °C tolerance would refuse;
    # without rate sensitivity only the curvature over the sweep limits it.
    t = np.arange(0.0, 7200.0, 60.0)
    y = approach(t, 40.0, 31.5, 900.0, PROBE_NOISE_C, seed=4)
    t_default, _ = first_stable(CFG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    t_no_lag, _ = first_stable(NO_LAG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    assert 8.5 * np.exp(-t_default / 900.0) > 0.2
    # ... and then the step tolerance binds: the die is within step_tol_c (1 °C) of its final
    # value at the sweep's start, but not nearer than it needs to be.
    offset_no_lag = 8.5 * np.exp(-t_no_lag / 900.0)
    assert t_no_lag < t_default and 0.5 < offset_no_lag <= NO_LAG.step_tol_c
    assert within_budgets(8.5 * np.exp(-t_no_lag / 900.0), 900.0, NO_LAG)
    strict = StabilityConfig(die_tol_c=0.1)
    t_strict, _ = first_stable(strict, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    assert t_strict > t_default and 8.5 * np.exp(-t_strict / 900.0) < 0.1 + 3 * PROBE_NOISE_C


def test_extreme_step_waits_for_the_valid_range() -> None:
    t = np.arange(0.0, 7200.0, 60.0)
    y = approach(t, -40.0, -10.0, 900.0, PROBE_NOISE_C, seed=8)
    t_inner, _ = first_stable(NO_LAG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    t_edge, _ = first_stable(NO_LAG, t, y, sweep_s=SWEEP_S, edge=True)  # type: ignore[misc]
    assert t_edge > t_inner
    _, _, mean_off = sweep_error_c(30.0 * np.exp(-t_edge / 900.0), 900.0, SWEEP_S, 0.0)
    assert mean_off <= NO_LAG.edge_tol_c


def test_a_rate_sensitive_sensor_needs_a_longer_soak() -> None:
    # The common (rate-lag) error is not averaged over the positions: the more the output
    # lags the die, the slower the die must move before the sweep starts.
    t = np.arange(0.0, 7200.0, 60.0)
    y = approach(t, 20.0, 10.0, 900.0, PROBE_NOISE_C, seed=3)
    times = [first_stable(StabilityConfig(gradient_lag_s=lag), t, y, sweep_s=SWEEP_S)[0]  # type: ignore[index]
             for lag in (0.0, 10.0, 40.0)]
    assert times[0] < times[1] < times[2]
    rate_c_per_s = 10.0 * np.exp(-times[2] / 900.0) / 900.0
    assert 40.0 * rate_c_per_s <= 1.2 * CFG.temp_budget_c / math.sqrt(CFG.n_positions)


def test_a_longer_sweep_needs_a_longer_soak() -> None:
    t = np.arange(0.0, 7200.0, 60.0)
    y = approach(t, 20.0, 10.0, 900.0, PROBE_NOISE_C, seed=2)
    t_short, _ = first_stable(NO_LAG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    t_long, _ = first_stable(NO_LAG, t, y, sweep_s=4 * SWEEP_S)  # type: ignore[misc]
    assert t_long > t_short


@pytest.mark.parametrize(("a_fast", "a_slow", "tau_slow_s"),
                         [(6.0, 3.0, 2400.0), (3.0, 6.0, 1800.0), (8.0, 2.0, 3600.0)])
def test_a_hidden_slow_time_constant_keeps_the_accuracy_budget(
        a_fast: float, a_slow: float, tau_slow_s: float) -> None:
    # Fast package lag on top of a slow fixture whose curvature is still below the probe
    # noise when the fast part has settled: no fit can see it, but its near-linear
    # contribution is what the per-step line absorbs, so the sweep stays within budget.
    def curve(t: np.ndarray) -> np.ndarray:
        return 20.0 - a_fast * np.exp(-t / 240.0) - a_slow * np.exp(-t / tau_slow_s)

    t = np.arange(0.0, 7200.0, 60.0)
    y = curve(t) + np.random.default_rng(6).normal(0, PROBE_NOISE_C, t.size)
    t_stable, d = first_stable(CFG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    assert d.reason == "die_predicted_within_tol"  # type: ignore[attr-defined]
    assert true_within_budgets(curve, t_stable)


def test_a_visible_slow_time_constant_is_waited_for() -> None:
    # A large slow component bends the history: the fit follows it and the step is
    # measured only once the die is within the step tolerance as well.
    def curve(t: np.ndarray) -> np.ndarray:
        return 20.0 - 6.0 * np.exp(-t / 240.0) - 10.0 * np.exp(-t / 2400.0)

    t = np.arange(0.0, 7200.0, 60.0)
    y = curve(t) + np.random.default_rng(6).normal(0, PROBE_NOISE_C, t.size)
    t_stable, d = first_stable(CFG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    assert d.reason == "die_predicted_within_tol"  # type: ignore[attr-defined]
    assert d.tau_s > 1000.0  # type: ignore[attr-defined]  # the slow constant, not the fast one
    # (+0.5 °C: a first-order fit through a two-constant tail slightly underestimates it)
    assert 20.0 - curve(np.array([t_stable]))[0] <= CFG.step_tol_c + 0.5
    assert true_within_budgets(curve, t_stable, slack=1.0)


def test_flat_history_is_stable_soon_after_min_soak() -> None:
    t = np.arange(0.0, 3600.0, 60.0)
    y = 25.0 + np.random.default_rng(3).normal(0, PROBE_NOISE_C, t.size)
    t_stable, d = first_stable(CFG, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    assert d.reason in ("die_flat", "die_predicted_within_tol")  # type: ignore[attr-defined]
    assert t_stable < CFG.max_soak_s / 2


def test_never_stable_reaches_max_soak() -> None:
    # A die that keeps drifting linearly (a chamber that never settles its load).
    t = np.arange(0.0, 7300.0, 60.0)
    y = 10.0 + 0.0005 * t + np.random.default_rng(1).normal(0, 0.03, t.size)
    decisions = [decide(CFG, float(t[k - 1]), True, t[:k], y[:k]) for k in range(2, t.size + 1)]
    firsts = [d for d in decisions if d.stable]
    assert firsts and firsts[0].reason == "max_soak_reached" and firsts[0].max_soak_reached


def test_oscillating_die_reaches_max_soak() -> None:
    # A chamber controller hunting ±1 °C with a 20 min period that the PV band misses
    # (e.g. a PV probe far from the load): the die is never a first-order approach.
    t = np.arange(0.0, 7300.0, 60.0)
    y = 20.0 + 0.4 * np.sin(2 * np.pi * t / 1200.0) + np.random.default_rng(2).normal(
        0, PROBE_NOISE_C, t.size)
    firsts = [d for k in range(2, t.size + 1)
              if (d := decide(CFG, float(t[k - 1]), True, t[:k], y[:k])).stable]
    assert firsts[0].reason == "max_soak_reached"


@pytest.mark.parametrize("pv", ["oscillating", "stuck_outside"])
def test_unsettled_or_stuck_pv_reaches_max_soak(pv: str) -> None:
    t = np.arange(0.0, 7300.0, 60.0)
    if pv == "oscillating":
        pv_c = 20.0 + 0.8 * np.sin(2 * np.pi * t / 600.0)
    else:
        pv_c = np.full(t.size, 19.2)  # the PV register froze during the ramp
    wsp_c = np.full(t.size, 20.0)
    die = approach(t, 20.0, 15.0, 600.0, PROBE_NOISE_C, seed=9)  # the die itself is fine
    first = None
    for k in range(2, t.size + 1):
        ok = chamber_settled(t[:k], pv_c[:k], wsp_c[:k], 20.0, CFG.tol_c, CFG.dwell_s)
        d = decide(CFG, float(t[k - 1]), ok, t[:k], die[:k])
        if d.stable:
            first = d
            break
    assert first is not None and first.max_soak_reached and first.reason == "max_soak_reached"


def test_stuck_pv_inside_the_band_does_not_shortcut_the_die() -> None:
    t = np.arange(0.0, 7200.0, 60.0)
    pv_c = np.full(t.size, 20.05)  # frozen, but inside the band: the chamber "looks" settled
    wsp_c = np.full(t.size, 20.0)
    die = approach(t, 20.0, 10.0, 900.0, PROBE_NOISE_C, seed=5)
    for k in range(2, t.size + 1):
        ok = chamber_settled(t[:k], pv_c[:k], wsp_c[:k], 20.0, CFG.tol_c, CFG.dwell_s)
        d = decide(CFG, float(t[k - 1]), ok, t[:k], die[:k], sweep_s=SWEEP_S)
        if d.stable:
            break
    assert within_budgets(10.0 * np.exp(-t[k - 1] / 900.0), 900.0)


def test_very_noisy_history_is_not_trusted_early() -> None:
    t = np.arange(0.0, 1500.0, 60.0)
    y = approach(t, 20.0, 10.0, 600.0, 0.5, seed=5)  # noise 15x the probe noise
    d = decide(CFG, float(t[-1]), True, t, y)
    assert not d.stable


def test_chamber_must_settle_first() -> None:
    t = np.arange(0.0, 1800.0, 60.0)
    y = np.full(t.size, 20.0)
    assert not decide(CFG, 1800.0, False, t, y).stable


def test_fixed_policy_waits_exactly_soak() -> None:
    fixed = StabilityConfig(policy="fixed", soak_s=3600.0)
    assert not decide(fixed, 3599.0, True, np.array([]), np.array([])).stable
    assert decide(fixed, 3600.0, False, np.array([]), np.array([])).stable


def test_dwell_policy_ignores_the_die() -> None:
    dwell = StabilityConfig(policy="dwell", soak_s=1800.0)
    t = np.arange(0.0, 1900.0, 60.0)
    y = approach(t, 20.0, 0.0, 3000.0, PROBE_NOISE_C)  # far from soaked
    assert not decide(dwell, 1700.0, True, t, y).stable
    assert decide(dwell, 1800.0, True, t, y).reason == "chamber_dwell_and_soak"


def test_chamber_settled_needs_continuous_dwell_at_target() -> None:
    t = np.arange(0.0, 600.0, 60.0)
    pv = np.full(t.size, 20.1)
    wsp = np.full(t.size, 20.0)
    assert chamber_settled(t, pv, wsp, 20.0, 0.3, 300.0)
    pv[-3] = 20.5  # left the band 2 polls ago: the dwell restarts
    assert not chamber_settled(t, pv, wsp, 20.0, 0.3, 300.0)
    wsp[:] = 19.0  # still ramping
    assert not chamber_settled(t, np.full(t.size, 20.0), wsp, 20.0, 0.3, 300.0)


def test_unknown_policy_is_rejected() -> None:
    with pytest.raises(ValueError, match="policy"):
        StabilityConfig(policy="magic")


# --- the measured rate sensitivity (service.engine.rate_gain) -----------------------------
def synthetic_soaks(k_ug_per_c_per_min: np.ndarray, seed: int = 0, n_steps: int = 10,
                    out_noise_ug: float = 17.7,
                    orientation: str = "pos23") -> list[SoakProbes]:
    """Soak probes of a staircase: die approaches (τ 900 s) from 7 °C short of each setpoint,
    output = a cubic f(T) per axis + k·dT/dt + noise (200-sample probes)."""
    rng = np.random.default_rng(seed)
    tempco = np.array([[80.0, -60.0, 40.0], [0.4, 0.2, -0.3], [0.003, -0.002, 0.001]])
    soaks = []
    for j in range(n_steps):
        t_inf = -30.0 + 10.0 * j
        t = np.arange(0.0, 2400.0, 60.0)
        die = t_inf - 7.0 * np.exp(-t / 900.0)
        rate = 60.0 * 7.0 / 900.0 * np.exp(-t / 900.0)  # °C/min
        f = sum(np.outer(die**(d + 1), tempco[d]) for d in range(3))
        out_ug = f + np.outer(rate, k_ug_per_c_per_min) + rng.normal(0, out_noise_ug, (t.size, 3))
        soaks.append(SoakProbes(orientation, t + 5000.0 * j,
                                die + 1.3 + rng.normal(0, 0.007, t.size), out_ug * 1e-6))
    return soaks


@pytest.mark.parametrize("k", [0.0, 100.0])
def test_rate_gain_is_recovered_from_the_soaks(k: float) -> None:
    true_k = k * np.array([1.0, -0.6, 0.4])
    est = estimate_rate_gain(synthetic_soaks(true_k, seed=int(k)))
    assert est is not None and est.soaks == 10
    assert np.all(np.abs(est.gain_ug_per_c_per_min - true_k) <= 3 * est.sd_ug_per_c_per_min)
    assert np.all(est.sd_ug_per_c_per_min < 10.0)  # informative enough to shorten a soak


def synthetic_first_ramp(k_ug_per_c_per_min: np.ndarray, seed: int = 0,
                         ambient_c: float = 23.0, first_c: float = -40.0,
                         ramp_c_per_min: float = 2.0, tau_s: float = 900.0,
                         soak_s: float = 3600.0) -> list[SoakProbes]:
    """The first ramp (air ambient → first setpoint at the ramp rate) and the first soak:
    the die lags the air first-order (τ), probed every 60 s with 250 samples; output a
    cubic f(T) + k·dT/dt + noise. Returns [ramp, soak]."""
    rng = np.random.default_rng(seed)
    tempco = np.array([[80.0, -60.0, 40.0], [0.4, 0.2, -0.3], [0.003, -0.002, 0.001]])
    ramp_s = (ambient_c - first_c) / ramp_c_per_min * 60.0
    dt = 1.0
    t = np.arange(0.0, ramp_s + soak_s, dt)
    air = np.maximum(first_c, ambient_c - ramp_c_per_min / 60.0 * t)
    die = np.empty_like(t)
    die[0] = ambient_c
    for i in range(1, t.size):  # exact step of the first-order lag for a piecewise-linear air
        die[i] = air[i] + (die[i - 1] - air[i]) * np.exp(-dt / tau_s)
    rate = 60.0 * (air - die) / tau_s  # °C/min
    probe = np.arange(60, t.size, 60)
    f = sum(np.outer(die[probe] ** (d + 1), tempco[d]) for d in range(3))
    out_ug = f + np.outer(rate[probe], k_ug_per_c_per_min) \
        + rng.normal(0, 8.9, (probe.size, 3))  # 250 samples: 140 µg / √250
    read = die[probe] + 1.3 + rng.normal(0, 0.006, probe.size)
    # the air reaches its band ≈ when the ramp ends: the soak starts there
    ramp = t[probe] < ramp_s
    return [SoakProbes("home", t[probe][m], read[m], out_ug[m] * 1e-6, is_ramp)
            for m, is_ramp in ((ramp, True), (~ramp, False))]


@pytest.mark.parametrize("k", [0.0, 100.0])
def test_the_first_ramp_and_soak_measure_the_rate_gain(k: float) -> None:
    """k from the first ramp: one ramp and the soak after it separate k (the rate is a
    trapezoid in T there), precisely enough to replace the prior during the first soak;
    the soak alone (a first-order approach: rate linear in T) says nothing."""
    true_k = k * np.array([1.0, -0.6, 0.4])
    ramp, soak = synthetic_first_ramp(true_k, seed=int(k) + 1)
    assert estimate_rate_gain([soak]) is None
    est = estimate_rate_gain([ramp, soak])
    assert est is not None and est.soaks == 2
    assert np.all(np.abs(est.gain_ug_per_c_per_min - true_k) <= 3 * est.sd_ug_per_c_per_min)
    assert is_informative(est)  # 2σ ≤ 50: the first soak need not wait on the prior
    # the ramp's rate comes from its readings: edges dropped, the ramp rate reached
    t_r, r_r = ramp.rate
    assert np.isnan(r_r[0]) and np.isnan(r_r[-1])
    assert -2.0 < np.nanmin(r_r) < -1.5 and np.nanmax(r_r) < 0.0


def test_a_ramp_counted_as_a_soak_would_bias_the_rate_gain() -> None:
    """Why a ramp's rate is its readings' and not a fitted approach: the die lags a moving
    air, which no first-order approach to a fixed value describes."""
    true_k = 100.0 * np.array([1.0, -0.6, 0.4])
    ramp, soak = synthetic_first_ramp(true_k, seed=5)
    as_soak = dataclasses.replace(ramp, ramp=False)
    wrong = estimate_rate_gain([as_soak, soak])
    right = estimate_rate_gain([ramp, soak])
    assert right is not None
    assert np.all(np.abs(right.gain_ug_per_c_per_min - true_k) <= 3 * right.sd_ug_per_c_per_min)
    assert wrong is None or np.any(np.abs(wrong.gain_ug_per_c_per_min - true_k)
                                   > 3 * wrong.sd_ug_per_c_per_min)


def test_one_soak_per_orientation_says_nothing_about_the_rate_gain() -> None:
    soaks = synthetic_soaks(np.zeros(3), n_steps=3)
    lone = [dataclasses.replace(s, orientation=f"o{i}") for i, s in enumerate(soaks)]
    assert estimate_rate_gain(lone) is None
    assert estimate_rate_gain(soaks[:1]) is None


def test_rate_gain_for_the_decision_prior_cap_and_lift() -> None:
    assert rate_gain_for_decision(None) == PRIOR_RATE_GAIN_UG_PER_C_PER_MIN
    weak = RateGain(np.array([5.0, 0.0, 0.0]), np.array([80.0, 80.0, 80.0]), 100, 2)
    assert rate_gain_for_decision(weak) == PRIOR_RATE_GAIN_UG_PER_C_PER_MIN
    sharp = RateGain(np.array([2.0, -1.0, 0.0]), np.array([3.0, 3.0, 3.0]), 400, 10)
    assert rate_gain_for_decision(sharp) == pytest.approx(8.0)
    worse = RateGain(np.array([180.0, 0.0, 0.0]), np.array([30.0, 3.0, 3.0]), 400, 10)
    assert rate_gain_for_decision(worse) == pytest.approx(180.0)  # not informative yet
    typical = RateGain(np.array([95.0, 0.0, 0.0]), np.array([6.0, 3.0, 3.0]), 400, 10)
    assert rate_gain_for_decision(typical) == pytest.approx(107.0)  # the bound, not the prior


def test_a_measured_rate_gain_sets_the_lag() -> None:
    assert lag_from_rate_gain_s(100.0, 150.0) == pytest.approx(40.0)
    with pytest.raises(ValueError):
        lag_from_rate_gain_s(-1.0, 150.0)
    t = np.arange(0.0, 7200.0, 60.0)
    temp = approach(t, 30.0, 25.0, 900.0, PROBE_NOISE_C, seed=3)
    via_gain = first_stable(CFG, t, temp, sweep_s=SWEEP_S, rate_gain_ug_per_c_per_min=100.0)
    via_lag = first_stable(StabilityConfig(soak_s=3600.0, gradient_lag_s=40.0), t, temp,
                           sweep_s=SWEEP_S)
    none = first_stable(CFG, t, temp, sweep_s=SWEEP_S, rate_gain_ug_per_c_per_min=0.0)
    assert via_gain is not None and via_lag is not None and none is not None
    assert via_gain[0] == via_lag[0]
    assert none[0] < via_gain[0]  # no rate sensitivity measured: a shorter soak


def test_an_approaching_die_predicts_when_it_will_be_stable() -> None:
    """``ready_in_s`` from a decision 10 min before the true first stable poll lands within
    a short poll (15 s) and 15 % of it: the runner may poll then, not a period later."""
    tau_s, step_s = 900.0, 15.0
    t = np.arange(0.0, 7200.0, step_s)
    temp = approach(t, -30.0, -38.5, tau_s, 0.005, seed=3)  # 250-sample probe noise
    got = first_stable(CFG, t, temp, sweep_s=SWEEP_S)
    assert got is not None
    t_stable = got[0]
    k0 = int(np.searchsorted(t, t_stable - 600.0))
    early = decide(CFG, float(t[k0]), True, t[: k0 + 1], temp[: k0 + 1], sweep_s=SWEEP_S)
    assert not early.stable and early.reason == "die_approaching"
    assert early.ready_in_s is not None
    assert early.ready_in_s == pytest.approx(t_stable - t[k0], rel=0.15, abs=step_s)


def test_next_poll_is_sooner_only_when_predicted_and_never_below_the_minimum() -> None:
    assert next_poll_s(Decision(False, "die_approaching", ready_in_s=25.0), 60.0, 15.0) == 25.0
    assert next_poll_s(Decision(False, "die_approaching", ready_in_s=3.0), 60.0, 15.0) == 15.0
    assert next_poll_s(Decision(False, "die_approaching", ready_in_s=600.0), 60.0, 15.0) == 60.0
    assert next_poll_s(Decision(False, "fit_not_credible"), 60.0, 15.0) == 60.0
    assert next_poll_s(Decision(False, "x", ready_in_s=math.inf), 60.0, 15.0) == 60.0
    waiting = decide(CFG, 420.0, True, np.arange(0.0, 421.0, 60.0), np.zeros(8))
    assert waiting.reason == "min_soak_waiting" and waiting.ready_in_s == pytest.approx(180.0)


def test_an_order_repeated_at_every_step_budgets_the_slot_error_over_the_steps() -> None:
    """When every step visits the positions in one order, the curvature the per-step line
    cannot follow meets the same position at every step: its budget is a position mean's
    noise over those steps (temp_budget_c / √steps), so the soak is longer and the true
    varying error at its end within that smaller budget."""
    loose = dataclasses.replace(NO_LAG, step_tol_c=5.0)  # only the curvature binds
    tau_s = 900.0
    t = np.arange(0.0, 7200.0, 30.0)
    y = approach(t, 40.0, 31.5, tau_s, 0.005, seed=5)
    once, _ = first_stable(loose, t, y, sweep_s=SWEEP_S)  # type: ignore[misc]
    every, _ = first_stable(loose, t, y, sweep_s=SWEEP_S, order_repeats=11)  # type: ignore[misc]
    assert every > once + 300.0

    def curve(u: np.ndarray) -> np.ndarray:
        return 40.0 - 8.5 * np.exp(-u / tau_s)

    varying, _ = true_sweep_errors_c(curve, every, SWEEP_S, 0.0)
    assert varying <= loose.temp_budget_c / math.sqrt(11)
    varying_once, _ = true_sweep_errors_c(curve, once, SWEEP_S, 0.0)
    assert varying_once > loose.temp_budget_c / math.sqrt(11)
