"""A temperature channel's LSB read from capture means that are averages of its codes
(plateau_noise.mean_code_lsb_c, issue 22).

A channel quantised at 0.5 °C whose noise is a tenth of that does not dither: each
plateau's mean of its codes keeps a rounding error up to ±0.25 °C. Its capture means lie on
a lattice of LSB/n, which shows the LSB as surely as a declared ``sensor_lsb_c``.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.discrepancy.diagnose import diagnose
from calibration.discrepancy.plateau_noise import mean_code_lsb_c
from calibration.recording import Recording
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

LSB_C = 0.5
N_SAMPLES = 200


def means_of_codes(die_c: np.ndarray, lsb_c: float, noise_c: float, decimals: int,
                   rng: np.random.Generator, offset_c: float = 0.37) -> np.ndarray:
    """Each reading's channel: the mean of N_SAMPLES codes of (die + offset + noise)."""
    samples = die_c[:, None] + offset_c + rng.normal(0.0, noise_c, (die_c.size, N_SAMPLES))
    return np.round(np.mean(np.round(samples / lsb_c) * lsb_c, axis=1), decimals)


def plateaus(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    steps = np.repeat(np.arange(6), 24)
    die = np.array([-40.0, -20.0, 0.0, 20.0, 40.0, 60.0])[steps] + rng.uniform(-0.3, 0.3, 6)[steps]
    return die + rng.normal(0.0, 0.01, steps.size), steps


def test_the_lsb_is_read_from_means_of_codes_and_nothing_from_a_continuous_channel():
    rng = np.random.default_rng(1)
    die, steps = plateaus(rng)
    n = np.full(die.size, float(N_SAMPLES))
    coded = means_of_codes(die, LSB_C, 0.05, 5, rng)
    assert mean_code_lsb_c(coded, n, steps) == pytest.approx(LSB_C, rel=0.01)
    assert mean_code_lsb_c(np.round(die + rng.normal(0, 0.02, die.size), 5), n, steps) is None
    # Written to 2 decimals the lattice (0.0025 °C) is below the writing: not read.
    assert mean_code_lsb_c(means_of_codes(die, LSB_C, 0.05, 2, rng), n, steps) is None
    assert mean_code_lsb_c(coded, None, steps) is None


def test_a_coarse_channel_without_dither_is_not_a_mismatch_and_the_report_says_why():
    # Setpoints off the codes by different fractions of an LSB: each plateau's rounding
    # error differs (the same one on every plateau would be a channel offset).
    truth = SensorTruth.adxl355_typical(seed=3)
    truth.coeffs[0:3, 1] = 0.1e-3  # bias tempco 0.1 mg/°C (the datasheet's ±0.15 at most)
    sim = simulate_campaign(truth, [-39.69, -19.55, 0.31, 20.45, 40.31, 59.55],
                            seed=3, soak_min=120, return_truth=True)
    cols = dict(sim.recording.columns)
    cols["sensor_c"] = means_of_codes(sim.die_c, LSB_C, 0.1, 5, np.random.default_rng(3))
    d = diagnose(Recording.from_columns(cols), seed=0)
    assert d.mismatch is False, [f.explanation for f in d.findings]
    said = [x for x in d.notes if "read from its capture means" in x]
    assert said and "quantised at 0.5 °C" in said[0] and "sensor_lsb_c" in said[0]
