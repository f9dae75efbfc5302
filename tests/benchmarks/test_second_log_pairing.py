"""The second-warm-up benchmark's pure pieces (benchmarks/bench_warmup_second_log.py): the
second log is the same sensor (every truth field kept, the same noiseless output for the
same profile) with another profile and other noise; the ArduPilot driver's filter runs
over contiguous fit runs; the bootstrap's ratio interval of two known series.
No real recordings needed (no vibration pool)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.bench_warmup_peers import blocks, fit_runs
from benchmarks.bench_warmup_second_log import (
    TAU_FACTOR,
    second_case,
    second_noise_seed,
    whole_ratio_interval,
)
from benchmarks.blind.gen2.warmup import die_temperature_c, draw_case, simulate

PROFILE_FIELDS = {"name", "start_c", "span_c", "tau_s"}


@pytest.mark.parametrize("seed", [1000, 1026, 1035])
def test_the_second_case_keeps_every_truth_field_and_changes_the_profile(seed: int) -> None:
    first = draw_case(seed)
    second = second_case(first)
    for f in dataclasses.fields(first):
        if f.name not in PROFILE_FIELDS:
            assert getattr(second, f.name) == getattr(first, f.name), f.name
    assert second.name != first.name
    assert second.start_c > first.start_c
    assert second.start_c + second.span_c == pytest.approx(first.start_c + first.span_c)
    assert TAU_FACTOR[0] <= second.tau_s / first.tau_s <= TAU_FACTOR[1]
    t = np.linspace(0.0, first.duration_s, 50)
    assert not np.allclose(die_temperature_c(first, t), die_temperature_c(second, t))


def test_another_noise_seed_is_the_same_sensor_with_other_noise() -> None:
    case = dataclasses.replace(draw_case(1026), duration_s=60.0, vib_sd_g=0.0)
    a = simulate(case)
    b = simulate(case, noise_seed=second_noise_seed(case))
    np.testing.assert_array_equal(a.true_g, b.true_g)
    assert not np.allclose(a.acc_g, b.acc_g)


def test_fit_runs_are_the_split_blocks_or_one_whole_run() -> None:
    t = np.arange(0.0, 60.0, 0.5)
    k, fit = blocks(t)
    runs = fit_runs(fit)
    assert [sorted(set(k[r])) for r in runs] == [[0], [2], [4]]
    assert all(np.all(k[r] == k[r][0]) and r.sum() == np.sum(k == k[r][0]) for r in runs)
    (whole,) = fit_runs(np.ones(t.size, bool))
    assert whole.all()


def test_the_ratio_interval_of_a_scaled_error_is_its_scale() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 600.0, 0.1)
    err = np.repeat(rng.normal(size=(t.size // 50, 3)), 50, axis=0)  # one value per 5 s
    peer = 1.0 + 1e-3 * err
    ours = 1.0 + 2e-3 * err * np.array([1.0, 0.5, 2.0])
    worse = 1.0 + 1e-3 * (err + np.array([[1.0, 0.0, 0.0]]) * np.sign(err[:, :1]))
    (x, y, z) = whole_ratio_interval(t, ours, (peer, worse), draws=200)
    assert x == pytest.approx([2.0, 2.0])
    assert y == pytest.approx([1.0, 1.0])
    assert z == pytest.approx([4.0, 4.0])


def test_a_dropout_longer_than_a_block_breaks_a_fit_run() -> None:
    t = np.concatenate([np.arange(0.0, 10.0, 0.5), np.arange(25.0, 30.0, 0.5)])
    runs = fit_runs(np.ones(t.size, bool), t)
    assert [int(r.sum()) for r in runs] == [20, 10]
