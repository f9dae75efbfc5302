"""The held-out error decomposition of a warm-up (benchmarks/bench_warmup_residual): its
noise surrogates keep the noise's spectrum, the still part's fit/held-out offset is read
as it is, and its fixed model families score a log whose answer is known."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_warmup_peers import WarmupLog, blocks
from benchmarks.bench_warmup_residual import allan_mg, families, split_parts, surrogate


def _five_s_sd(noise: np.ndarray, per_s: int) -> np.ndarray:
    m = 5 * per_s
    nb = noise.shape[0] // m
    return noise[: nb * m].reshape(nb, m, 3).mean(axis=1).std(axis=0)


def test_surrogate_keeps_the_slow_noise_a_white_draw_would_lose():
    """Noise with a slow part (a random walk, high-passed over 100 s) beside white noise:
    the 5-s means of its surrogates scatter as the noise's own do, several times more than
    white noise of the same per-sample SD would."""
    per_s, n = 50, 50 * 600
    rng = np.random.default_rng(3)
    walk = np.cumsum(rng.standard_normal((n, 3)), axis=0) * 2e-6
    kernel = np.ones(100 * per_s) / (100 * per_s)
    slow = walk - np.column_stack([np.convolve(walk[:, a], kernel, "same") for a in range(3)])
    noise = slow + 1e-5 * rng.standard_normal((n, 3))
    own = _five_s_sd(noise, per_s)
    white = noise.std(axis=0) / np.sqrt(5 * per_s)
    assert np.all(own > 3 * white)
    draws = np.array([_five_s_sd(surrogate(noise, n, rng), per_s) for _ in range(8)])
    ratio = np.sqrt(np.mean(draws ** 2, axis=0)) / own
    assert np.all((ratio > 0.7) & (ratio < 1.4))


def test_allan_deviation_of_white_noise_falls_as_one_over_root_tau():
    per_s = 100
    rng = np.random.default_rng(5)
    ad = allan_mg(1e-3 * rng.standard_normal((per_s * 400, 3)), per_s)
    r = np.array(ad["0.1"]) / np.array(ad["1"])  # 400 one-second means: ±4 %
    assert np.all((r > 0.85 * np.sqrt(10)) & (r < 1.15 * np.sqrt(10)))


def _rest_then_heat(rate_gain_g: float, seed: int = 1) -> WarmupLog:
    """100 s at rest at 20 °C, then a heating whose rate rises smoothly to 6 °C/min over
    40 s (a parabola over 40 s follows it) and holds: z = 1 g + 1 mg/°C·(T − 20) +
    rate_gain_g·dT/dt, white noise 0.5 mg per sample at 100 Hz. 210 s: the last 10-s
    block is fitted, so no held-out temperature lies beyond the fit span (clamped)."""
    t = np.arange(0.0, 210.0, 0.01)
    rate = 6.0 * np.sin(0.5 * np.pi * np.clip((t - 100.0) / 40.0, 0.0, 1.0)) ** 2
    T = 20.0 + np.cumsum(rate) * 0.01 / 60.0
    rng = np.random.default_rng(seed)
    z = 1.0 + 1e-3 * (T - 20.0) + rate_gain_g * rate + 5e-4 * rng.standard_normal(t.size)
    acc = np.column_stack([5e-4 * rng.standard_normal(t.size),
                           5e-4 * rng.standard_normal(t.size), z])
    return WarmupLog("rest-then-heat", t, acc, T)


def test_a_rate_term_family_scores_a_rate_sensitive_log_a_static_one_does_not():
    """A part whose z reads 0.1 mg per °C/min beside a 1 mg/°C slope: the family with the
    rate term leaves the held-out error near the noise of a 5-s mean, the static one not;
    without a rate sensitivity the static one is as good."""
    noise_5s_mg = 0.5 / np.sqrt(500)
    for gain, static_worse in ((1e-4, True), (0.0, False)):
        got = {f["model"]: f["heldout_mg"] for f in families(_rest_then_heat(gain))}
        with_rate = got["degree 1 + k·dT/dt (40 s)"][2]
        static = got["degree 1"][2]
        assert with_rate < 3 * noise_5s_mg
        assert bool(static > 5 * noise_5s_mg) is static_worse


def test_the_still_offset_is_the_held_out_means_less_the_fit_means_at_rest():
    """At rest (dT/dt 0) the held-out blocks read 0.3 mg below the fit blocks: no function of
    temperature can move that, and split_parts reports it as the still offset."""
    t = np.arange(0.0, 200.0, 1.0)
    _, fit = blocks(t)
    rows = [{"t_s": float(v), "T_c": 20.0, "rate_c_per_min": 0.0, "held_out": bool(not f),
             "m": [0.0, 0.0, 0.0 if f else -0.3]} for v, f in zip(t[::5], fit[::5], strict=True)]
    parts = split_parts(rows, "m")
    assert parts["n_changing"] == 0
    assert np.isclose(parts["still_offset_mg"][2], -0.3)
    assert np.isclose(parts["rms_still_mg"][2], 0.3)
