"""Warm-up logs whose rows are single samples: a bias change far beyond its standard error
is established even where it is a fraction of a percent of the rows' own noise, and noisy
captures of one face fit nothing absolutely that they do not see (calibration/warmup.py,
calibration/warmup_absolute.py)."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_warmup_single_sample_rows import first_stage_errors
from calibration import sfem, warmup
from calibration.gate import Orientations
from calibration.recording import Recording
from calibration.warmup_absolute import absolute_part, identified, visible

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


def test_noisy_captures_of_one_face_fit_nothing_absolutely_they_do_not_see():
    # Six captures of the z-up face whose directions scatter by a few degrees (single-sample
    # rows of a noisy log read as capture means): the identifiability check counts them as
    # determining the angle ayx, although it moves |g| at second order only, below the
    # visible columns. The absolute part reports as determined only what it fits (it
    # raised IndexError on an empty Jacobian).
    tilts = np.array([[-0.054, 0.114], [-0.087, -0.097], [-0.055, 0.042], [0.089, -0.089],
                      [0.031, -0.028], [0.049, 0.04]])
    d = np.column_stack([tilts, np.ones(len(tilts))])
    d /= np.linalg.norm(d, axis=1)[:, None]
    assert "ayx" in identified(d, "norm") and "ayx" not in visible(d, "norm")
    per = 8
    labels = np.repeat(np.arange(len(d)), per)
    temp_c = np.tile(np.linspace(20.0, 30.0, per), len(d))
    raw = d[labels] + np.random.default_rng(0).normal(0.0, 1e-4, (labels.size, 3))
    captures = Recording.from_columns({"t_s": np.arange(labels.size) * 5.0, "sensor_c": temp_c,
                                       "ax": raw[:, 0], "ay": raw[:, 1], "az": raw[:, 2]})
    orientations = Orientations(labels, d, np.full(len(d), per), 1.0)
    fit_abs = absolute_part(captures, orientations, (temp_c - 25.0) / 5.0,
                            sfem.identity_vector()[:, None], 1, np.arange(labels.size) % 2,
                            None, 1.0)
    assert set(fit_abs.names) <= set(visible(d, "norm"))
    assert "ayx" not in fit_abs.names
