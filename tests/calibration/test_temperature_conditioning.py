"""Temperature conditioning at compensation time: per step, or the causal filter."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.temperature_conditioning import (
    _local_fit,
    causal_filter,
    channel_quantum_c,
    compensation_temperature,
    segments_for_conditioning,
    smooth_many_over_time,
    smooth_over_time,
    temperature_rate_c_per_min,
    temperature_rates_c_per_min,
)


def test_causal_filter_averages_noise_on_a_plateau() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 5.0  # 5 s per row, 10 000 s
    noisy = 25.0 + rng.normal(0, 0.1, t.size)
    out = causal_filter(t, noisy, tau_s=600.0)
    settled = t > 1200.0
    # effective averaging ~ tau / 1.25 = 480 s = 96 rows: sd 0.1 / sqrt(96) ~ 0.010 °C
    assert np.std(out[settled] - 25.0) < 0.02
    assert abs(np.mean(out[settled]) - 25.0) < 0.005


def test_causal_filter_follows_a_ramp_without_lag() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(3000) * 2.0
    truth = 60.0 - t / 60.0  # cooling at 1 °C/min: a first-order average of 600 s lags 10 °C
    out = causal_filter(t, truth + rng.normal(0, 0.1, t.size), tau_s=600.0)
    late = t > 1800.0
    assert abs(np.mean(out[late] - truth[late])) < 0.02
    assert np.max(np.abs(out[late] - truth[late])) < 0.1


def test_causal_filter_uses_no_future_rows() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(500) * 10.0
    y = 20.0 + rng.normal(0, 0.1, t.size)
    a = causal_filter(t, y)
    y2 = y.copy()
    y2[300:] += 5.0
    b = causal_filter(t, y2)
    np.testing.assert_array_equal(a[:300], b[:300])
    assert not np.allclose(a[300:], b[300:])


def test_causal_filter_ignores_one_spike_and_restarts_on_a_jump() -> None:
    t = np.arange(100) * 10.0
    y = np.full(100, 20.0)
    y[30] = 40.0  # one spike
    y[60:] = 35.0  # a real jump to another soak temperature
    out = causal_filter(t, y)
    # the spike row keeps its own reading, but does not enter the filter
    assert out[30] == 40.0 and abs(out[31] - 20.0) < 1e-9
    assert out[60] == 35.0  # first row at the new temperature: its own reading
    np.testing.assert_allclose(out[61:], 35.0, atol=1e-9)


def test_segments_split_on_step_setpoint_and_temperature_jumps() -> None:
    temp = np.r_[np.full(5, -35.0), np.full(5, -5.0), np.full(5, 25.0)]
    step = np.zeros(15)  # a verification run writing one step index for every soak
    seg = segments_for_conditioning(step, None, temp)
    assert seg is not None and len(np.unique(seg)) == 3
    assert segments_for_conditioning(None, None, temp) is None


def test_compensation_temperature_per_step_when_there_are_steps() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(120) * 30.0
    die = np.repeat([-35.0, -5.0, 25.0, 55.0], 30)
    noisy = die + rng.normal(0, 0.1, die.size)
    sp = np.round(die)
    per_step, how = compensation_temperature(t, noisy, None, sp)
    assert "per step" in how
    assert np.sqrt(np.mean((per_step - die) ** 2)) < 0.04  # ~0.1/sqrt(30) plus line slope
    causal, how2 = compensation_temperature(t, noisy, None, None)
    assert "causal filter" in how2 and "600 s" in how2
    # a setpoint per row (a ramp) is no step structure: the causal filter is used
    _, how3 = compensation_temperature(t, noisy, None, np.arange(120.0))
    assert "causal filter" in how3


def test_settled_step_gets_its_mean_and_a_creeping_step_its_line() -> None:
    from calibration.temperature_conditioning import condition_temperature

    rng = np.random.default_rng(4)
    t = np.arange(48) * 15.0
    steps = np.repeat([0, 1], 24)
    settled = 25.0 + rng.normal(0, 0.1, 24)
    creeping = 35.0 + 0.002 * (t[24:] - t[24]) + rng.normal(0, 0.1, 24)  # 0.7 °C over the step
    cond = condition_temperature(t, np.r_[settled, creeping], steps)
    assert np.ptp(cond.row_c[:24]) == 0.0  # a slope that is only noise is dropped
    assert cond.row_c[:24][0] == pytest.approx(np.mean(settled))
    slope = np.polyfit(t[24:], cond.row_c[24:], 1)[0]
    assert slope == pytest.approx(0.002, rel=0.2)  # a real creep is kept


@pytest.mark.parametrize(("true_c", "noise_c"), [(20.02, 0.012), (20.035, 0.02)])
def test_a_quantised_channel_is_not_thrown_away_but_a_glitch_still_is(
        true_c: float, noise_c: float) -> None:
    # A settled die read in 0.06 °C steps with less noise than a step: most readings
    # share a level, the robust sigma is a fraction of a step (or a rounding error),
    # and "more than 4 robust sigma" threw away every reading off that level.
    from calibration.temperature_conditioning import channel_quantum_c, condition_temperature

    rng = np.random.default_rng(5)
    t = np.arange(3000) * 0.2
    read = np.round((true_c + rng.normal(0, noise_c, t.size)) / 0.06) * 0.06
    assert channel_quantum_c(read) == pytest.approx(0.06)
    c = condition_temperature(t, read, np.zeros(t.size, int))
    assert c.rejected_rows == 0
    assert abs(c.step_c[0] - true_c) < 0.015  # the mean of honest readings
    read[1234] += 1.2  # a glitch of twenty quanta
    assert condition_temperature(t, read, np.zeros(t.size, int)).rejected_rows == 1
    assert channel_quantum_c(20.0 + rng.normal(0, 0.01, 500)) == 0.0  # not quantised


@pytest.mark.parametrize("degree", [1, 2])
def test_smoothing_all_windows_at_once_equals_window_by_window(degree: int) -> None:
    """The batched local fits (moment sums, sorted-window medians) are the row-by-row
    robust polyfit, to rounding: on a quantised, noisy ramp with a glitch, across a jump,
    with windows too short for a polynomial at the ends of a run."""
    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(5.0, 25.0, 300))
    temp = 20.0 + 30.0 * np.sin(t / 2500.0) + rng.normal(0.0, 0.1, t.size)
    temp = np.round(temp / 0.11) * 0.11
    temp[[40, 90, 200]] += 4.0  # single-row glitches the robust refit drops
    temp[150:] += 12.0  # a jump: two runs
    got = smooth_over_time(t, temp, 300.0, degree=degree)
    seg = np.r_[np.zeros(150, int), np.ones(t.size - 150, int)]
    quantum = channel_quantum_c(temp)
    want = np.empty(t.size)
    for s in (0, 1):
        idx = np.flatnonzero(seg == s)
        ts, ys = t[idx], temp[idx]
        for j, i in enumerate(idx):
            win = np.abs(ts - ts[j]) <= 150.0
            want[i] = _local_fit(ts[win], ys[win], ts[j], degree, quantum)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert np.max(np.abs(got - temp)) > 1.0  # the glitches were smoothed away, not kept


def test_many_series_at_once_are_each_series_alone() -> None:
    """Draws of noise read at one set of times (how dT/dt's noise is measured) give, smoothed
    together, what each gives alone (to rounding: batched sums may round differently): rows
    cut at different jumps, a quantised series, a missing reading (its run window by window)
    and gaps between runs."""
    rng = np.random.default_rng(5)
    t = np.cumsum(np.where(np.arange(120) % 30 == 29, 12.0, 1.0))
    Y = 20.0 + 0.02 * t + rng.normal(0.0, 0.05, (6, t.size))
    Y[1, 70:] += 2.0  # cut at a jump no other row has
    Y[2] = np.round(Y[2] / 0.0625) * 0.0625
    Y[3, 10] = np.nan
    for degree in (1, 2):
        together = smooth_many_over_time(t, Y, 20.0, degree=degree)
        alone = np.vstack([smooth_over_time(t, y, 20.0, degree=degree) for y in Y])
        np.testing.assert_allclose(together, alone, rtol=1e-12, atol=0)
    rates = temperature_rates_c_per_min(t, Y, 10.0)
    np.testing.assert_allclose(
        rates, np.vstack([temperature_rate_c_per_min(t, y, 10.0) for y in Y]), rtol=0,
        atol=1e-9)
    assert np.all(np.isfinite(rates[0])) and abs(np.median(rates[0]) - 1.2) < 0.3  # °C/min


def _warmup_rows_with_gaps(pattern: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1-s rows of a die warming from 20 °C toward 35 °C (τ 300 s) with rows missing:
    ``blocks``, alternate 10-s blocks (a held-out split's fit rows); ``dropouts``, a log
    losing 2-8 s at a time. Returns (t_s, T, the analytic dT/dt in °C/min)."""
    t = np.arange(900.0)
    if pattern == "blocks":
        keep = (t // 10) % 2 == 0
    else:
        rng = np.random.default_rng(3)
        keep = np.ones(t.size, bool)
        for start in rng.choice(t.size - 10, 40, replace=False):
            keep[start:start + rng.integers(2, 9)] = False
    t = t[keep]
    return t, 20.0 + 15.0 * (1.0 - np.exp(-t / 300.0)), 3.0 * np.exp(-t / 300.0)


@pytest.mark.parametrize("pattern", ["blocks", "dropouts"])
def test_the_rate_beside_a_gap_is_the_rate_not_a_difference_across_it(pattern: str) -> None:
    # Over a 5-s window a row beside a gap has 3 rows on one side; the rate there must be
    # the curve's, as at any other row (a parabola's fallback to their median read a
    # 2 °C/min heating as 0.2-1.2 °C/min beside each gap)
    t, temperature, truth = _warmup_rows_with_gaps(pattern)
    rate = temperature_rate_c_per_min(t, temperature, 5.0)
    beside = np.r_[np.diff(t) > 1.5, False] | np.r_[False, np.diff(t) > 1.5]
    assert beside.sum() >= 40
    np.testing.assert_allclose(rate[beside], truth[beside], rtol=0.02)
    np.testing.assert_allclose(rate, truth, rtol=0.02)
