"""The second generator's one-orientation warm-up logs (benchmarks/blind/gen2/warmup.py):
its physics (a lagging channel lags, the channel's LSB, the noise density, the hysteresis
state), the written CSV is the true output plus noise only, and ``soakcal import --format
csv`` reads it back in the case's own unit. No real recordings needed (no vibration pool).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from benchmarks.blind.gen2.warmup import (
    MAX_OUT_HZ,
    MAX_ROWS,
    PROFILES,
    UNIT_SCALE,
    WarmupCase,
    bias_g,
    die_temperature_c,
    draw_case,
    first_order_lag,
    import_args,
    play_hysteresis,
    simulate,
    write_log,
)
from calibration.recording import read_recording

QUIET = dict(noise_density_ug_rthz=0.0, accel_lsb_g=0.0, vib_sd_g=0.0, channel_noise_c=0.0,
             channel_lsb_c=0.0, channel_offset_c=0.0, channel_lag_s=0.0)


def _case(**kw: object) -> WarmupCase:
    base = dataclasses.replace(draw_case(11), **QUIET)
    return dataclasses.replace(base, **kw)  # type: ignore[arg-type]


def test_a_first_order_lag_trails_a_ramp_by_its_time_constant() -> None:
    dt, tau, rate = 0.02, 30.0, 0.5  # °C/s
    t = np.arange(0, 600, dt)
    y = first_order_lag(rate * t, dt, tau)
    late = t > 10 * tau
    # exact for x held over each step: the steady lag is rate·(τ − dt/2 … τ), i.e. ≈ rate·τ
    np.testing.assert_allclose((rate * t - y)[late], rate * tau, rtol=2e-3)
    assert y[0] == 0.0 and np.all(np.diff(y) >= 0)


def test_a_lagging_channel_reads_colder_while_heating_and_warmer_while_cooling() -> None:
    case = _case(profile="heat_cool", duration_s=1800.0, tau_s=300.0, span_c=20.0,
                 out_hz=10.0, native_hz=10.0, channel_lag_s=60.0)
    d = simulate(case)
    heating = d.t_s < 0.5 * case.duration_s
    cooling = d.t_s > 0.6 * case.duration_s
    assert np.all((d.temp_c - d.die_c)[heating][50:] < 0)
    assert np.all((d.temp_c - d.die_c)[cooling] > 0)
    on_die = simulate(dataclasses.replace(case, channel_lag_s=0.0))
    np.testing.assert_allclose(on_die.temp_c, on_die.die_c)


@pytest.mark.parametrize("lsb", [0.0078125, 0.06, 1.0])
def test_the_channel_is_quantised_to_its_lsb(lsb: float) -> None:
    d = simulate(_case(channel_lsb_c=lsb, channel_noise_c=0.01, channel_offset_c=0.37))
    codes = d.temp_c / lsb
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)
    # and it is a reading of the die: within half an LSB plus the noise and the offset
    assert np.max(np.abs(d.temp_c - d.die_c - 0.37)) <= lsb / 2 + 0.06


def test_a_dithered_coarse_channel_is_the_same_case_with_a_noisy_whole_degree_channel() -> None:
    for seed in (1000, 1003, 1009):
        plain, dith = draw_case(seed), draw_case(seed, coarse_dither=True)
        # every draw but the channel's LSB and noise is the plain case's
        same = dataclasses.replace(dith, name=plain.name, channel_lsb_c=plain.channel_lsb_c,
                                   channel_noise_c=plain.channel_noise_c, kinds=plain.kinds)
        assert same == plain
        assert dith.channel_lsb_c == 1.0 and 0.1 <= dith.channel_noise_c <= 0.6
        assert "dither" in dith.kinds and "quant1C" in dith.kinds
    # its physics: whole degrees, and the share of readings one level up tracks where the
    # die sits inside its LSB (noise of half an LSB: the fraction's mean is the die's)
    c = dataclasses.replace(_case(channel_lsb_c=1.0, channel_noise_c=0.5), profile="heater",
                            duration_s=1800.0, span_c=6.0, tau_s=2000.0, out_hz=50.0,
                            native_hz=50.0)
    d = simulate(c)
    np.testing.assert_allclose(d.temp_c, np.round(d.temp_c), atol=1e-9)
    flips = int(np.sum(np.diff(d.temp_c) != 0))
    assert flips > 20 * 6  # many transitions per crossing, not one
    block = np.arange(d.t_s.size) // 1500  # 30-s means
    mean_read = np.bincount(block, d.temp_c) / np.bincount(block)
    mean_die = np.bincount(block, d.die_c) / np.bincount(block)
    assert np.max(np.abs(mean_read - mean_die)) < 0.08
    # the same channel without the noise: a staircase, wrong by up to half an LSB
    quiet = simulate(dataclasses.replace(c, channel_noise_c=0.0))
    assert int(np.sum(np.diff(quiet.temp_c) != 0)) <= 7
    assert np.max(np.abs(np.bincount(block, quiet.temp_c) / np.bincount(block) - mean_die)) > 0.3


def test_the_logged_csv_is_the_true_output_and_nothing_else_when_quiet(tmp_path) -> None:
    case = _case(accel_unit="mg", rate_ug_per_c_per_min=(40.0, -20.0, 10.0),
                 drift_ug_per_h=(30.0, 0.0, -30.0))
    d = simulate(case)
    csv_path, truth_path = write_log(case, d, tmp_path)
    data = np.loadtxt(csv_path, delimiter=",", skiprows=1)
    np.testing.assert_allclose(data[:, 1:4] / 1e3, d.true_g, atol=1e-9)
    np.testing.assert_allclose(data[:, 4], d.temp_c, atol=1e-5)
    truth = json.loads(truth_path.read_text())
    assert truth["case"]["name"] == case.name
    np.testing.assert_allclose(truth["true_change_mg"], np.ptp(d.true_g, 0) * 1e3)


def test_the_true_output_is_gravity_through_the_gain_plus_the_bias_path() -> None:
    """Take away the rate term: the change is exactly k·dT/dt of the die."""
    k = (60.0, -30.0, 15.0)
    with_rate = simulate(_case(profile="heater", rate_ug_per_c_per_min=k))
    without = simulate(_case(profile="heater"))
    rate_c_per_min = np.gradient(without.die_c, without.t_s) * 60.0
    np.testing.assert_allclose(with_rate.true_g - without.true_g,
                               rate_c_per_min[:, None] * np.asarray(k) * 1e-6, atol=1e-12)
    # the bias polynomial alone carries the drawn slope at the reference temperature
    case = _case()
    ref = np.array([case.bias_ref_c - 0.5, case.bias_ref_c + 0.5])
    slope = np.diff(bias_g(case, ref), axis=0)[0]
    assert np.all(np.abs(slope) >= 0.05e-3 * 0.5) and np.all(np.abs(slope) <= 2e-3 * 1.5)


def test_white_noise_is_at_the_density_after_averaging_down() -> None:
    case = _case(profile="heater", span_c=0.0, noise_density_ug_rthz=100.0, native_hz=400.0,
                 out_hz=50.0, duration_s=600.0)
    d = simulate(case)
    sd = (d.acc_g - d.true_g).std(axis=0)
    expected = 100e-6 * np.sqrt(400.0 / 2.0) / np.sqrt(8)
    np.testing.assert_allclose(sd, expected, rtol=0.03)


def test_the_acceleration_lsb_is_applied_at_the_native_rate() -> None:
    lsb = 0.5e-3
    d = simulate(_case(accel_lsb_g=lsb, native_hz=100.0, out_hz=100.0))
    codes = d.acc_g / lsb
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)


def test_hysteresis_goes_to_plus_while_heating_and_minus_while_cooling() -> None:
    temp = np.concatenate([np.linspace(20, 30, 200), np.linspace(30, 20, 200)])
    s = play_hysteresis(temp, width_c=1.0)
    assert s[199] > 0.99 and s[-1] < -0.99
    # it is a state, not a rate: the same temperature reads differently on the two legs
    assert s[100] - s[300] > 1.5


@pytest.mark.parametrize("profile", PROFILES)
def test_every_profile_starts_at_its_start_and_stays_in_its_span(profile: str) -> None:
    case = _case(profile=profile, start_c=10.0, span_c=20.0, duration_s=3600.0, tau_s=400.0)
    t = np.linspace(0, case.duration_s, 5000)
    die = die_temperature_c(case, t)
    assert abs(die[0] - 10.0) < 0.5
    assert die.min() > 10.0 - 0.5 and die.max() < 10.0 + 20.0 * 1.35  # overshoot allowed
    assert np.ptp(die) > 0.5 * 20.0


def test_drawn_cases_span_the_profiles_and_keep_files_modest() -> None:
    cases = [draw_case(s) for s in range(300)]
    assert {c.profile for c in cases} == set(PROFILES)
    for c in cases:
        assert 180.0 <= c.duration_s <= 3600.0 and 3.0 <= c.span_c <= 40.0
        assert c.out_hz <= MAX_OUT_HZ and c.out_hz * c.duration_s <= MAX_ROWS
        assert float(c.native_hz / c.out_hz).is_integer()
        assert abs(np.linalg.norm(c.up) - 1.0) < 1e-12
    kinds = {k for c in cases for k in c.kinds}
    assert {"lag", "rate", "quant1C", "hysteresis", "short", "drift"} <= kinds
    assert len({c.up for c in cases}) == len(cases)  # not only z up


@pytest.mark.parametrize("unit", sorted(UNIT_SCALE))
def test_soakcal_import_reads_the_log_back_in_g(tmp_path, unit: str) -> None:
    from service.cli import main

    case = _case(accel_unit=unit, duration_s=200.0, out_hz=20.0, native_hz=20.0,
                 channel_lsb_c=0.0078125)
    d = simulate(case)
    csv_path, _ = write_log(case, d, tmp_path)
    out = tmp_path / "rec.csv"
    assert main(["import", "--format", "csv", str(csv_path), "-o", str(out),
                 *import_args(case)]) == 0
    rec = read_recording(out)
    np.testing.assert_allclose(rec.raw_g, d.acc_g, atol=1e-8)
    np.testing.assert_allclose(rec.columns["sensor_c"], d.temp_c, atol=1e-5)
    np.testing.assert_allclose(rec.t_s, d.t_s, atol=1e-5)


def test_the_benchmark_verdicts_and_the_wilson_interval() -> None:
    from benchmarks.bench_warmup_gen2 import verdict, wilson

    lo, hi = wilson(0, 30)
    assert lo == 0.0 and 0.10 < hi < 0.12  # the rule of three's neighbour
    lo, hi = wilson(15, 30)
    assert lo < 0.5 < hi and abs((lo + hi) / 2 - 0.5) < 1e-12
    base = {"none": [1.0, 1.0, 1.0], "px4": [0.10, 0.2, 0.3], "ardupilot": [0.2, 0.1, 0.3],
            "oracle": [0.1, 0.1, 0.1]}
    assert verdict(base | {"soakcal": [0.1, 0.1, 0.3]})["outcome"] == "win"
    assert verdict(base | {"soakcal": [0.105, 0.1, 0.3]})["outcome"] == "win-within-floor"
    assert verdict(base | {"soakcal": [0.12, 0.1, 0.3]})["outcome"] == "loss"
    assert verdict(base | {"soakcal": None})["outcome"] == "refused-loss"
    # nothing compensates it: the better peer does not halve the uncompensated error
    bad = base | {"px4": [0.9, 0.9, 0.9], "ardupilot": [0.8, 0.8, 0.8], "soakcal": None}
    assert verdict(bad)["outcome"] == "refused-neutral"
