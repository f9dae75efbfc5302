"""Warm-ups read by a coarsely quantised temperature channel, shared by the rebuild's, the
rate noise's and the firmware export's tests. The die traces are the benchmark's
(benchmarks/bench_temperature_dequantise.py)."""

from __future__ import annotations

import numpy as np

from benchmarks import bench_temperature_dequantise as bench
from calibration.recording import Recording

RATE_HZ = 50.0
exponential, overshoot = bench.exponential, bench.overshoot
rest_heat_rest, heat_cool = bench.rest_heat_rest, bench.heat_cool


def captures(profile, noise_c: float, block_s: float, seed: int = 0, lsb_c: float = 1.0):
    """(capture times, capture-mean readings, capture-mean truth) of a channel read at
    50 Hz with ``noise_c`` of noise, rounded to ``lsb_c`` and averaged over ``block_s``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 1800.0, 1.0 / RATE_HZ)
    truth = profile(t)
    read = np.round((truth + rng.normal(0.0, noise_c, t.size)) / lsb_c) * lsb_c
    k = np.floor(t / block_s).astype(int)
    n = np.bincount(k)
    return (np.bincount(k, t) / n, np.bincount(k, read) / n, np.bincount(k, truth) / n)


def z_bias_g(die_c: np.ndarray) -> np.ndarray:
    """The warm-ups' true z bias: 1 mg/°C + 0.02 mg/°C² of the die temperature about 27 °C."""
    return 1e-3 * (die_c - 27.0) + 2e-5 * (die_c - 27.0) ** 2


def warmup_rows(lsb_c: float, profile=heat_cool, seed: int = 5) -> tuple[Recording, np.ndarray]:
    """5-s capture means of a board at rest (z up) whose z bias is :func:`z_bias_g` of its
    die temperature, read by a channel quantised at ``lsb_c``; and the true die temperature."""
    rng = np.random.default_rng(seed)
    t, read, die = captures(profile, 0.01, 5.0, seed=seed, lsb_c=lsb_c)
    n = t.size
    cols = {"t_s": t, "sensor_c": read, "ax": rng.normal(0, 2e-6, n),
            "ay": rng.normal(0, 2e-6, n), "az": 1.0 + z_bias_g(die) + rng.normal(0, 2e-6, n),
            "n": np.full(n, 250.0), "sd_x": np.full(n, 3e-5), "sd_y": np.full(n, 3e-5),
            "sd_z": np.full(n, 3e-5)}
    return Recording.from_columns(cols), die
