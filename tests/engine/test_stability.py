"""Stability decisions on synthetic die-temperature curves (pure functions)."""

from __future__ import annotations

import numpy as np
import pytest

from service.engine.stability import StabilityConfig, chamber_settled, decide, fit_approach

CFG = StabilityConfig(soak_s=3600.0, min_soak_s=600.0, max_soak_s=7200.0)


def approach(t_s: np.ndarray, t_inf: float, t0: float, tau_s: float, noise_c: float,
             seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return t_inf - (t_inf - t0) * np.exp(-t_s / tau_s) + rng.normal(0, noise_c, t_s.size)


def first_stable(cfg: StabilityConfig, t_s: np.ndarray, temp_c: np.ndarray) -> float | None:
    for k in range(2, t_s.size + 1):
        d = decide(cfg, float(t_s[k - 1]), True, t_s[:k], temp_c[:k])
        if d.stable:
            return float(t_s[k - 1])
    return None


def test_fit_recovers_tau_and_final_value() -> None:
    t = np.arange(0.0, 2400.0, 60.0)
    fit = fit_approach(t, approach(t, 20.0, 5.0, 600.0, 0.02))
    assert fit.ok
    assert fit.tau_s == pytest.approx(600.0, rel=0.05)
    assert fit.t_inf_c == pytest.approx(20.0, abs=0.05)
    assert fit.tau_sd_s < 0.1 * fit.tau_s


@pytest.mark.parametrize("tau_s", [300.0, 600.0, 900.0])
def test_declared_stable_only_when_die_is_within_tolerance(tau_s: float) -> None:
    t = np.arange(0.0, 7200.0, 60.0)
    y = approach(t, -30.0, -10.0, tau_s, 0.035, seed=int(tau_s))
    t_stable = first_stable(CFG, t, y)
    assert t_stable is not None
    true_offset_c = 20.0 * np.exp(-t_stable / tau_s)
    assert true_offset_c < 2 * CFG.die_tol_c  # the decision was right (within the noise)
    # ...and not wastefully late: within 2 τ of the ideal moment (offset == tol)
    ideal_s = tau_s * np.log(20.0 / CFG.die_tol_c)
    assert t_stable <= max(ideal_s + 2 * tau_s, CFG.min_soak_s + 600)


def test_flat_history_is_stable_after_min_soak() -> None:
    t = np.arange(0.0, 1800.0, 60.0)
    y = 25.0 + np.random.default_rng(3).normal(0, 0.03, t.size)
    t_stable = first_stable(CFG, t, y)
    assert t_stable is not None and CFG.min_soak_s <= t_stable <= CFG.min_soak_s + 120


def test_never_stable_reaches_max_soak() -> None:
    # A die that keeps drifting linearly (a chamber that never settles its load).
    t = np.arange(0.0, 7300.0, 60.0)
    y = 10.0 + 0.0005 * t + np.random.default_rng(1).normal(0, 0.03, t.size)
    decisions = [decide(CFG, float(t[k - 1]), True, t[:k], y[:k]) for k in range(2, t.size + 1)]
    firsts = [d for d in decisions if d.stable]
    assert firsts and firsts[0].reason == "max_soak_reached" and firsts[0].max_soak_reached


def test_very_noisy_history_is_not_trusted_early() -> None:
    t = np.arange(0.0, 1500.0, 60.0)
    y = approach(t, 20.0, 10.0, 600.0, 0.5, seed=5)  # noise 5x the die tolerance
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
