"""A channel so far from dithering that only one plateau shows its means of codes
(plateau_noise.mean_code_lsb_c, issue 22).

A 0.5 °C channel with 0.015 °C of noise holds one code through every settled plateau
whose die sits well inside a code; only a plateau whose die sits at a code's edge writes
means of two codes, on the lattice of LSB/n. With the other plateaus' codes on the
multiples of that LSB, the LSB is read as from a lattice on several plateaus.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.discrepancy.plateau_noise import mean_code_lsb_c

LSB_C = 0.5
N_SAMPLES = 304


def _channel(edge_fraction: np.ndarray, rng: np.random.Generator, decimals: int = 5):
    """Five plateaus of 40 readings, each the mean of N_SAMPLES codes of die + noise; the
    die sits ``edge_fraction`` of an LSB above a code, per plateau."""
    steps = np.repeat(np.arange(5), 40)
    codes = np.array([-78.0, -32.0, 23.0, 71.0, 122.0])  # code indices × LSB
    die = (codes + edge_fraction * LSB_C)[steps]
    samples = die[:, None] + rng.normal(0.0, 0.015, (steps.size, N_SAMPLES))
    means = np.mean(np.round(samples / LSB_C) * LSB_C, axis=1)
    return np.round(means, decimals), np.full(steps.size, float(N_SAMPLES)), steps


def test_one_plateau_at_a_codes_edge_shows_the_lsb():
    rng = np.random.default_rng(4)
    t, n, steps = _channel(np.array([0.1, -0.2, 0.05, 0.5, 0.3]), rng)
    held = [np.unique(t[steps == k]).size for k in range(5)]
    assert held.count(1) == 4 and max(held) >= 5  # one plateau shows a lattice
    assert mean_code_lsb_c(t, n, steps) == pytest.approx(LSB_C, rel=1e-4)


def test_codes_not_on_the_lattices_lsb_read_nothing():
    """The same lattice plateau beside held values that are not one channel's codes at
    that LSB (0.1 °C apart at random): no LSB."""
    rng = np.random.default_rng(4)
    t, n, steps = _channel(np.array([0.1, -0.2, 0.05, 0.5, 0.3]), rng)
    for k, shift in zip((0, 1, 2, 4), (0.1, 0.3, 0.2, 0.1), strict=True):
        t[steps == k] += shift
    assert mean_code_lsb_c(t, n, steps) is None
