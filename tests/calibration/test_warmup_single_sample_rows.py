"""Warm-up logs whose rows are single samples: a bias change far beyond its standard error
is established even where it is a fraction of a percent of the rows' own noise, and noisy
captures of one face fit nothing absolutely that they do not see (calibration/warmup.py,
calibration/warmup_absolute.py)."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_warmup_single_sample_rows import NOISE_G, first_stage_errors
from calibration import warmup
from calibration.fitting import fit
from calibration.recording import Recording

ROWS = 18000


def _held_out(change_g: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A warm-up of single-sample rows (20 mg white noise, z up, 20 → 30 °C) with a linear
    bias change of z, through the solver's own held-out machinery: the held-out errors of
    degree 0 and degree 1, (n, 3) g, and each held-out row's temperature block."""
    errors, held, block = first_stage_errors(ROWS, change_g, seed)
    return errors[0], errors[1], block[held]


def test_a_change_far_beyond_its_standard_error_is_evidence_at_any_share_of_the_noise():
    # 10 mg over the span: 0.3 % of the held-out RMS, far beyond its standard error
    low, high, block = _held_out(change_g=10e-3, seed=1)
    share = 1.0 - np.sqrt(np.mean(np.sum(high**2, 1)) / np.mean(np.sum(low**2, 1)))
    assert 0.0 < share < warmup.MIN_GAIN  # the rows' noise hides it from the share rule
    assert warmup._beats(low, high, block)
    assert warmup._beats(low[:, 2], high[:, 2], block)  # one axis' own question alike
    assert not warmup._beats(low[:, 0], high[:, 0], block)  # x has no change


def test_no_change_is_not_evidence():
    hits = sum(warmup._beats(*_held_out(change_g=0.0, seed=seed)) for seed in range(300))
    assert hits <= 3  # a one-sided 0.5 % level: at most 1.5 expected (the test is conservative)


def test_noisy_captures_of_one_face_are_calibrated_without_an_absolute_fit():
    # 20,000 single-sample rows of 20 mg noise, z up, no change: their directions scatter
    # by a degree, which the identifiability check counts as determining the angle ayx
    # although it moves |g| at second order only. The absolute fit fits nothing it does not
    # see (it raised IndexError on an empty Jacobian).
    rng = np.random.default_rng(33)
    n = 20000
    t = np.arange(n) * 2.0
    temp_c = 20.0 + 10.0 * t / t[-1]
    az = 1.0 + rng.normal(0.0, NOISE_G, n)
    ax, ay = rng.normal(0.0, NOISE_G, n), rng.normal(0.0, NOISE_G, n)
    rec = Recording.from_columns({"t_s": t, "sensor_c": temp_c + rng.normal(0.0, 0.02, n),
                                  "ax": ax, "ay": ay, "az": az})
    model = fit(rec).model
    assert model.degree == 0
    assert not any(k.startswith("fitted absolutely") for k in model.fitted.values())
