"""The per-axis model choice of benchmarks/bench_warmup_axis_choice: every step of the
warm-up solver's choice on one axis' held-out errors."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_warmup_axis_choice import per_axis_choice

CANDIDATES = [(0, 0), (1, 0), (2, 0), (2, 1)]


def _errors(scale_xyz: list[np.ndarray], n: int = 80, seed: int = 0
            ) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) held-out errors, each axis white noise of its own RMS, and their indices."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, 3)) * np.asarray(scale_xyz), np.arange(n)


def test_each_axis_takes_what_its_own_held_out_error_establishes():
    # Degree 0 → 2: z's held-out error falls 10-fold; y's by 1 % at every capture alike
    # (the same draw scaled: beyond MIN_GAIN and the gain's standard error), by 0.1 % at
    # degree 1 (below MIN_GAIN); x's not at all. A rate gain adds nothing anywhere.
    n = 80
    block = np.repeat(np.arange(8), n // 8)
    base, idx = _errors([1.0, 1.0, 1.0], n)
    deg = [(base * [1.0, 1.0, 1.0], idx), (base * [1.0, 0.999, 0.5], idx),
           (base * [1.0, 0.99, 0.1], idx)]
    rate = [(base * [1.0, 1.0, 1.0], idx), (base * [1.0, 0.999, 0.5], idx),
            (base * [1.0, 0.99, 0.1], idx), (base * [1.0, 0.99, 0.1], idx)]
    assert per_axis_choice(0, deg, rate, CANDIDATES, block) == (0, None)
    assert per_axis_choice(1, deg, rate, CANDIDATES, block) == (2, None)
    assert per_axis_choice(2, deg, rate, CANDIDATES, block) == (2, None)


def test_a_rate_term_alone_is_taken_where_it_establishes_a_change():
    n = 80
    block = np.repeat(np.arange(8), n // 8)
    base, idx = _errors([1.0, 1.0, 1.0], n, seed=1)
    deg = [(base, idx), (base, idx), (base, idx)]
    rate = [(base * [1.0, 1.0, 0.2], idx), (base * [1.0, 1.0, 0.2], idx),
            (base * [1.0, 1.0, 0.2], idx), (base * [1.0, 1.0, 0.2], idx)]
    assert per_axis_choice(2, deg, rate, CANDIDATES, block) == (0, 0)
    assert per_axis_choice(0, deg, rate, CANDIDATES, block) == (0, None)
