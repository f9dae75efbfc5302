"""Ramp recordings of the second generator (benchmarks/blind/gen2/ramp.py) through the one
fit entry: a valid continuous recording, a model near the noise-limited oracle, and a plain
statement when only the chamber air was recorded while it moved.

Noise pools are synthetic (white, unit sd) so the test needs no real recordings.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.blind.gen2.ramp import (
    RampSpec,
    air_program,
    die_lag,
    hold_minutes,
    ramp_record,
    static_readings,
    true_force_g,
)
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.fitting import fit
from calibration.recording import Recording


@pytest.fixture(scope="module")
def pools() -> NoisePools:
    rng = np.random.default_rng(3)
    return NoisePools(sensor=rng.standard_normal((20_000, 3)),
                      vibration=rng.standard_normal((20_000, 3)),
                      placement=rng.standard_normal(2_000))


# 3 °C/min: ~300 captures, a fit of a second or so
SPEC = RampSpec(rate_c_per_min=3.0, die_tau_s=400.0, n_samples=100, sensor_noise_g=60e-6,
                vib_sd_g=0.2e-3, rate_ug_per_c_per_min=20.0, hysteresis_ug=15.0)


def test_the_ramp_is_a_valid_recording_with_no_plateau_and_the_die_behind_the_air(
        pools: NoisePools) -> None:
    cols, truth = ramp_record(SPEC, draw_sensor(np.random.default_rng(1)), pools, seed=5)
    rec = Recording.from_columns(cols)
    assert rec.has_reference and rec.temperature_source == "sensor_c"
    assert "step" not in cols and "setpoint_c" not in cols
    # heating: the die is behind (colder than) the air; its channel reads the die
    up = truth.direction > 0
    assert np.median(truth.air_c[up] - truth.die_c[up]) > 5.0
    assert np.max(np.abs(cols["sensor_c"] - truth.die_c)) < 0.1
    assert truth.die_c.min() < -39.0 and truth.die_c.max() > 30.0
    assert np.all(np.diff(cols["t_s"]) > 0)


def test_the_fit_of_a_small_ramp_is_near_the_noise_limited_oracle(pools: NoisePools) -> None:
    sensor = draw_sensor(np.random.default_rng(1))
    cols, truth = ramp_record(SPEC, sensor, pools, seed=5)
    result = fit(Recording.from_columns(cols))
    assert result.kind == "continuous"
    rng = np.random.default_rng(9)
    v = rng.normal(size=(120, 3))
    refs = v / np.linalg.norm(v, axis=1, keepdims=True)
    die = np.repeat([-30.0, -10.0, 10.0, 25.0], 30)  # inside the die's range
    raw = static_readings(sensor, pools, refs, die, seed=11, sensor_noise_g=60e-6,
                          vib_sd_g=0.2e-3)
    model_err = np.sqrt(np.mean(np.sum((result.model.compensate(raw, die) - refs) ** 2, 1)))
    oracle_err = np.sqrt(np.mean(np.sum((true_force_g(sensor, raw, die) - refs) ** 2, 1)))
    uncompensated = np.sqrt(np.mean(np.sum((raw - refs) ** 2, 1)))
    # loose physical bound: within 1.5× the oracle, where raw readings are ~1000× off
    assert model_err < 1.5 * oracle_err < 0.01 * uncompensated


def test_a_ramp_with_only_the_chamber_air_says_the_die_temperature_is_unknown(
        pools: NoisePools) -> None:
    sensor = draw_sensor(np.random.default_rng(1))
    both, _ = ramp_record(SPEC, sensor, pools, seed=5)
    air = {k: v for k, v in both.items() if k != "sensor_c"}
    on_air = fit(Recording.from_columns(air))
    assert on_air.kind == "continuous"
    said = [n for n in on_air.notes if "only chamber_c" in n]
    assert len(said) == 1 and "sensor_c" in said[0]
    ident = on_air.report["identified"]
    assert any("die temperature" in s for s in ident["not_identified"])
    assert not any(s.startswith("rate sensitivity") for s in ident["identified"])
    assert any(s.startswith("the sensor's own rate sensitivity") for s in ident["not_identified"])
    on_die = fit(Recording.from_columns(both))
    assert not any("only chamber_c" in n for n in on_die.notes)


def test_a_leg_too_short_for_the_rate_term_is_said_not_left_out(pools: NoisePools) -> None:
    sensor = draw_sensor(np.random.default_rng(1))
    short = RampSpec(**{**SPEC.__dict__, "end_c": 40.0})  # the die barely turns back
    cols, truth = ramp_record(short, sensor, pools, seed=5)
    assert np.any(truth.direction < 0)
    lines = fit(Recording.from_columns(cols)).report["identified"]["not_identified"]
    said = [s for s in lines if s.startswith("rate sensitivity and hysteresis: a leg is too")]
    assert len(said) == 1 and "cooling" in said[0]
    long_legs = fit(Recording.from_columns(ramp_record(SPEC, sensor, pools, seed=5)[0]))
    assert not any("a leg is too short" in s
                   for s in long_legs.report["identified"]["not_identified"])


def test_the_plan_program_runs_soakcal_legs_with_holds_only_at_the_turnarounds() -> None:
    spec = RampSpec(**{**SPEC.__dict__, "program": "plan"})
    air = air_program(spec)
    assert air[0] == air[-1] == spec.safe_c
    # the cold end first, then the hot end, then back: every temperature crossed both ways
    assert np.argmin(air) < np.argmax(air)
    moving = np.diff(air)
    standing = np.flatnonzero(moving == 0)
    assert set(np.unique(air[standing])) == {spec.low_c, spec.high_c}
    die = die_lag(air, spec.die_tau_s)
    for end in (spec.low_c, spec.high_c):
        held = np.flatnonzero(air == end)
        # the hold ends when the die is within the gap; it was far away when the air arrived
        assert abs(die[held[-1]] - end) <= spec.edge_gap_c < abs(die[held[0]] - end)
    holds = hold_minutes(spec)
    tau_min = spec.die_tau_s / 60.0
    rate_lag_c = spec.rate_c_per_min * tau_min
    first_order = tau_min * np.log(rate_lag_c / spec.edge_gap_c)  # ramp-campaigns.md
    assert all(0.8 * first_order < h <= first_order for h in holds)
    assert hold_minutes(SPEC) == []


def test_a_plan_ramp_fits_continuously_with_both_legs_long_enough(pools: NoisePools) -> None:
    spec = RampSpec(**{**SPEC.__dict__, "program": "plan"})
    cols, truth = ramp_record(spec, draw_sensor(np.random.default_rng(1)), pools, seed=5)
    # while the air holds at the low end the hysteresis state is still "cooling"
    at_low = np.abs(truth.air_c - spec.low_c) < 1e-9
    assert at_low.any() and np.all(truth.direction[at_low] < 0)
    result = fit(Recording.from_columns(cols))
    assert result.kind == "continuous"
    assert not any("a leg is too short" in s
                   for s in result.report["identified"]["not_identified"])
    assert truth.die_c.min() < spec.low_c + spec.edge_gap_c
    assert truth.die_c.max() > spec.high_c - spec.edge_gap_c
