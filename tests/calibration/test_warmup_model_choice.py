"""The model of an established bias change: the simplest within MIN_GAIN of the lowest
held-out error, among every degree ≥ 1 with and without a rate term.

The held-out figures are those `calibrate --json` reports (``degree_selection``,
``rate_selection``, mg) on the fit rows of three warm-ups of issue 20's benchmark
(`benchmarks/bench_warmup_peers.py`'s 10-s fit blocks): two from the second generator
(`benchmarks/blind/gen2/warmup.py`, seeds 1001 and 1059) and a real inclinometer log.
"""

from __future__ import annotations

import pytest

from calibration import warmup

# (d, m) rate candidates in the order fit_warmup builds them (simplest first)
CANDIDATES = [(0, 0), (1, 0), (2, 0), (2, 1), (3, 0), (3, 1), (3, 2)]


def test_one_more_degree_is_taken_over_a_rate_term_that_does_no_better():
    # gen2 w1001, a 4-min ramp: degree 2 with a rate gain (0.0798 mg) was kept because it
    # beat degree 2 alone (0.0816) beyond its standard error, while degree 3 without it
    # does as well (0.0797); the firmwares' cubic matched degree 3 on held-out 5-s means.
    totals = [2.4633, 0.2145, 0.0816, 0.0797]
    with_rate = [2.5271, 0.1924, 0.0798, 0.0839, 0.0807, 0.0906, 0.0806]
    assert warmup._choose_model(totals, with_rate, CANDIDATES) == (3, None)


def test_a_weak_curvature_is_kept_once_a_change_is_established():
    # gen2 w1059, a 22-min heat-cool at the noise level: degree 2 lowers held-out RMS by
    # 0.4 %, within that gain's standard error, so the degree test stopped at a line. A
    # change is established (degree 1 beats 0 by 98 %); among its models degree 2 is the
    # simplest within MIN_GAIN of the lowest (a rate gain 0.0517, 0.2 % lower, is not).
    totals = [3.4192, 0.0520, 0.0518, 0.0518]
    with_rate = [3.2410, 0.0518, 0.0517, 0.0517, 0.0517, 0.0517, 0.0519]
    assert warmup._choose_model(totals, with_rate, CANDIDATES) == (2, None)


def test_a_rate_term_that_lowers_held_out_error_well_beyond_min_gain_is_kept():
    # the inclinometer: degree 2 with a constant rate gain, 0.6021 mg against 0.7053 at
    # degree 2 alone and 0.7033 at degree 3
    totals = [1.6679, 0.8651, 0.7053, 0.7033]
    with_rate = [1.0008, 0.7687, 0.6021, 0.6262, 0.6232, 0.647]
    cands = CANDIDATES[:6]
    assert warmup._choose_model(totals, with_rate, cands) == (2, cands.index((2, 0)))


@pytest.mark.parametrize("lowest", [0, 1, 2])
def test_more_coefficients_must_buy_more_than_min_gain(lowest):
    # three models within MIN_GAIN of each other: the simplest, wherever the lowest is
    totals = [1.0, 0.5, 0.5, 0.5]
    totals[1 + lowest] *= 1.0 - 0.5 * warmup.MIN_GAIN
    assert warmup._choose_model(totals, [], []) == (1, None)
    totals[3] = 0.5 * (1.0 - 2.0 * warmup.MIN_GAIN)
    assert warmup._choose_model(totals, [], []) == (3, None)
