"""Held-out folds that test the term, not the base's temperature polynomial (issue 22).

With five plateaus and a cubic in temperature, holding out an interior plateau leaves a
cubic fitted exactly through the four others: the held-out error is that cubic's
interpolation error, common to the model with and without the term, and a real term's
change of the four fitted plateaus moved it up or down at random (second generator, case
0005: a cross coupling at 2× its detectable size, p_family 6·10⁻¹², "held-out RMS 37.63 →
37.97 µg with its term", not named). Such a recording is now held out by interleaved visit
groups of every plateau (``heldout.visit_group_folds``); a recording whose plateaus
over-determine the polynomial keeps leave-one-step-out.

Recordings come from the second generator with synthetic noise pools (as
test_gen2_power.py: the benchmark's pools come from real recordings outside the repository).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.discrepancy.heldout import N_INTERVALS, folds, training_levels
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _record(seed: int, kind: str, eid: str | None = None, m: float = 0.0) -> Recording:
    rng = np.random.default_rng(700 + seed)
    pr = protocol.draw_protocol(rng, kind=kind, schedule="oblique36", columns=("sensor_c",),
                                soak_min=20.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "vib_sd_g": tuple(0.0 for _ in pr.setpoints_c)})
    sensor = draw_sensor(rng)
    p = fx.pattern(rng, len(pr.setpoints_c), 10)
    return Recording.from_columns(sim.record(pr, sensor, _pools(), eid, m, p, seed))


def test_five_plateaus_are_held_out_by_visits_of_every_plateau():
    """Five temperatures, a cubic: no interior plateau can be held out without fitting the
    cubic exactly through the rest, so every fold keeps readings of every plateau."""
    pb = build_problem(_record(1, "sparse"))
    ctx = pb.ctx
    assert len(ctx.step_ids) == 5 and pb.degree == 3
    assert all(training_levels(ctx.step_temp_c, s) == pb.degree + 1 for s in ctx.step_ids[1:-1])
    masks, scheme = folds(ctx, pb.degree)
    assert scheme.startswith("leave-one-visit-group-out")
    assert len(masks) == N_INTERVALS
    held = np.sum(masks, axis=0)
    assert np.all(held == 1)  # every reading held out exactly once
    for m in masks:
        assert set(np.unique(ctx.steps[~m])) == set(ctx.step_ids)  # trained on every plateau
        assert set(np.unique(ctx.steps[m])) == set(ctx.step_ids)  # and tested on every one
    # A position is held out on some plateaus and seen on others (a per-pose term has
    # seen it), never on all of them at once.
    for m in masks:
        for pos in np.unique(ctx.positions):
            at = ctx.positions == pos
            assert not np.all(m[at]) or np.unique(ctx.steps[at]).size == 1


def test_plateaus_that_overdetermine_the_cubic_keep_leave_one_step_out():
    """Six or more temperatures: every interior plateau left out still leaves five, more
    than the cubic's four coefficients; the folds are the interior steps as before."""
    pb = build_problem(_record(2, "oneway"))
    ctx = pb.ctx
    assert len(ctx.step_ids) >= 6
    masks, scheme = folds(ctx, pb.degree)
    assert scheme == "leave-one-step-out (interior steps)"
    assert len(masks) == len(ctx.step_ids) - 2
    for m, s in zip(masks, ctx.step_ids[1:-1], strict=True):
        assert np.array_equal(m, ctx.steps == s)


def test_a_degenerate_fold_is_dropped_and_the_rest_kept():
    """A lower polynomial degree (fewer temperatures) changes which folds are informative:
    with degree 2 the five-plateau recording's interior steps each leave four
    temperatures, more than three coefficients, so they are held out whole."""
    pb = build_problem(_record(1, "sparse"))
    masks, scheme = folds(pb.ctx, 2)
    assert scheme == "leave-one-step-out (interior steps)" and len(masks) == 3


def test_a_cross_coupling_on_five_plateaus_is_named_with_a_held_out_gain():
    """A cross coupling of 40 µg/g² (5–10× the detectable sizes the benchmark drew) on a
    five-setpoint schedule of oblique positions: named, and its held-out figure, from
    visits of every plateau, falls with its term."""
    d = diagnose(_record(3, "sparse", "cross_coupling", 40.0), seed=0, n_null=100)
    assert d.heldout_scheme.startswith("leave-one-visit-group-out")
    (f,) = [f for f in d.findings if f.effect == "cross_coupling"]
    assert f.heldout_rmse_after_ug < f.heldout_rmse_before_ug
