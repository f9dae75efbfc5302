"""The PX4 peer of the warm-up benchmarks (benchmarks/bench_warmup_peers.px4_script_fit)
does what PX4's ``Tools/process_sensor_caldata.py`` does to a log, step by step: a
31-sample median filter per axis, the reading less its median, the mean of each of 2000
equal temperature bins, then a cubic in T − TREF. Checked here on logs whose answer is
known without the script."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_warmup_peers import WarmupLog, px4_script_fit


def _quantised_log(seed: int = 4) -> WarmupLog:
    """A board at rest read at 50 Hz by a 0.5 °C channel, its x offset a quartic in the
    reading (no cubic fits it; a staircase the median filter leaves as it is), and most of
    the time spent at the hot end (a warm-up that settles): uneven dwell per level."""
    t = np.arange(0.0, 1200.0, 0.02)
    die = 20.0 + 10.0 * (1.0 - np.exp(-t / 150.0))
    reading = np.round(die * 2.0) / 2.0
    x_g = 1e-3 * ((reading - 25.0) / 5.0) ** 4
    rng = np.random.default_rng(seed)
    acc = np.column_stack([x_g, 1e-6 * rng.standard_normal(t.size),
                           1.0 + 1e-6 * rng.standard_normal(t.size)])
    return WarmupLog("quantised", t, acc, reading)


def test_each_temperature_level_counts_once_whatever_its_dwell():
    """On a quantised channel every non-empty bin is one level: the cubic is the
    unweighted least-squares cubic through the levels' mean offsets, not the fit to every
    sample (which the long rest at the hot end would dominate)."""
    log = _quantised_log()
    fit = np.ones(log.t_s.size, bool)
    coef, t_min, t_max, t_ref = px4_script_fit(log, fit)
    assert (t_min, t_max, t_ref) == (20.0, 30.0, 25.0)
    levels = np.unique(log.temp_c)
    x = log.acc_g[:, 0]
    x_ok = x - np.median(x)
    means = np.array([x_ok[log.temp_c == v].mean() for v in levels])
    expected = np.polyfit(levels - t_ref, means, 3)
    np.testing.assert_allclose(coef[0], expected, rtol=1e-9, atol=1e-15)
    per_sample = np.polyfit(log.temp_c - t_ref, x_ok, 3)
    assert np.max(np.abs(coef[0] - per_sample)) > 1e-5  # g: the weighting matters here


def test_a_spike_shorter_than_the_median_window_does_not_move_the_fit():
    log = _quantised_log()
    fit = np.ones(log.t_s.size, bool)
    clean = px4_script_fit(log, fit)[0]
    spiked = log.acc_g.copy()
    spiked[30_000:30_005, 2] += 0.5  # g: five samples, under half the 31-sample window
    hit = px4_script_fit(WarmupLog("spiked", log.t_s, spiked, log.temp_c), fit)[0]
    # the filter moves the spike's neighbours by a noise sample at most (1e-6 g here);
    # unfiltered, the spike would shift its level's mean by about 1e-3 g
    np.testing.assert_allclose(hit, clean, rtol=0, atol=1e-9)
