"""The second-warm-up benchmark's pure pieces (benchmarks/bench_warmup_second_log.py): the
second log is the same sensor (every truth field kept, the same noiseless output for the
same profile) with another profile and other noise; the ArduPilot driver's filter runs
over contiguous fit runs; the bootstrap's ratio interval of two known series; the
second log flown from its own first poll (``--as-flown``); the part of the second log
beyond the first's span scored apart.
No real recordings needed (no vibration pool)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.bench_warmup_peers import (
    WarmupLog,
    blocks,
    fit_runs,
    insample_rms_mg,
    method_ardupilot,
    method_px4,
)
from benchmarks.bench_warmup_second_log import (
    TAU_FACTOR,
    beyond_span,
    flown_compare,
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


def test_the_second_log_is_flown_from_its_own_first_poll() -> None:
    """``--as-flown``: the peers' files are fitted on the first log and flown on the second
    from the second's own first sample. A second warm-up that moves 0.8 °C (under PX4's
    1 °C gate) keeps the first poll's offset throughout: PX4 flown leaves the whole change
    (a per-sample application removes it), while ArduPilot's 1-Hz filter follows a slow
    ramp (0.08 °C/min) as closely as per sample. Without a model there is no soakcal file."""
    t = np.arange(0.0, 600.0, 0.1)
    slope_g_per_c = np.array([0.0, 0.5e-3, 1e-3])

    def log(name: str, temp_c: np.ndarray) -> WarmupLog:
        return WarmupLog(name, t, 0.3 + temp_c[:, None] * slope_g_per_c, temp_c)

    first = log("a", np.linspace(20.0, 30.0, t.size))
    second = log("b", np.linspace(24.0, 24.8, t.size))
    n1 = t.size
    fit = np.zeros(2 * n1, bool)
    fit[:n1] = True
    joined = WarmupLog("j", np.concatenate([t, t + t[-1] + 1e4]),
                       np.vstack([first.acc_g, second.acc_g]),
                       np.concatenate([first.temp_c, second.temp_c]))
    methods = {"px4": method_px4(joined, fit)[n1:],
               "ardupilot": method_ardupilot(joined, fit)[0][n1:]}
    f = flown_compare(joined, fit, second, methods, np.ones(n1, bool), [0.0, 0.0, 0.0],
                      None)
    change_mg = insample_rms_mg(second, second.acc_g)  # the change left uncompensated
    assert change_mg[2] == pytest.approx(1e3 * 0.8e-3 / np.sqrt(12.0), rel=0.02)
    assert f["px4_publications"] == 1
    np.testing.assert_allclose(f["px4_flown_peer"], change_mg, rtol=1e-6, atol=1e-9)
    assert np.max(f["px4_per_sample_peer"]) < 1e-3
    assert np.max(f["ardupilot_flown_peer"]) < 1e-3
    assert f["ardupilot_lag_max_c"] < 1e-3
    assert f["px4_flown"] is None and f["ardupilot_flown"] is None
    assert "px4_flown_verdict" not in f


def test_the_part_beyond_the_first_logs_span_is_scored_apart() -> None:
    """A second warm-up that ends 1 °C above the first's span: every method clamps there, so
    the whole-log figure holds the uncompensated change beyond the edge; over the 5-s means
    inside soakcal's edges (the first log's 1-s rows) an exact compensation scores ~0. A
    second log inside the span has nothing beyond."""
    t = np.arange(0.0, 600.0, 0.1)
    slope_g_per_c = np.array([1e-3, 0.0, -1e-3])
    first = WarmupLog("a", t, np.zeros((t.size, 3)), np.linspace(20.0, 30.0, t.size))
    first.acc_g = first.temp_c[:, None] * slope_g_per_c
    temp2 = np.linspace(22.0, 31.0, t.size)
    second = WarmupLog("b", t, temp2[:, None] * slope_g_per_c, temp2)
    rows_lo, rows_hi = 20.0 + 0.45 / 60.0, 30.0 - 0.45 / 60.0  # 1-s rows: means 0.45 s in
    exact = second.acc_g - np.clip(temp2, rows_lo, rows_hi)[:, None] * slope_g_per_c
    methods = {"px4": exact, "ardupilot": exact, "soakcal": exact}
    b = beyond_span(first, second, methods, np.ones(t.size, bool), None)
    assert b is not None
    assert b["rows_edges_c"] == pytest.approx([rows_lo, rows_hi], abs=1e-3)
    assert b["sample_edges_c"] == pytest.approx([20.0, 30.0])
    assert b["means_outside"] == pytest.approx(120 / 9, abs=1.5)  # the last 1 °C of 9
    whole_mg = insample_rms_mg(second, exact)  # clamped beyond the edge: about 0.1 mg
    assert whole_mg[0] > 0.05
    # inside: ~0 (the last mean inside straddles the edge by < 5 s of samples)
    assert np.max(b["soakcal"]) < 0.02 * whole_mg[0]
    inside = WarmupLog("c", t, second.acc_g, np.linspace(22.0, 29.0, t.size))
    assert beyond_span(first, inside, methods, np.ones(t.size, bool), None) is None
