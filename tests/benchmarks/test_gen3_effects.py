"""benchmarks/blind/gen3/effects (issue 22): a drawn catalogue effect adds what its
docstring says on top of the null's own draws, and its size follows the drawn noise."""

import dataclasses

import numpy as np
from scipy.stats import norm

from benchmarks.blind.gen3.case import draw_case, simulate
from benchmarks.blind.gen3.effects import (
    channel_noise,
    detectable_amplitude,
    draw_effect,
    noncentrality,
    rounding_variance,
    zigzag,
)
from benchmarks.blind.gen3.noise import NoiseSpec
from benchmarks.blind.gen3.protocol import Protocol
from benchmarks.blind.gen3.schedules import faces


def _case(seed, setpoints, order="random", density=(20e-6, 25e-6, 30e-6)):
    """A drawn case cut to the given plateaus × 6 faces × 2 visits on a table, white
    noise only, a fine temperature channel."""
    case = draw_case(seed)
    protocol = Protocol(setpoints_c=setpoints, order=order, schedule_name="faces",
                        directions=faces(), visits=2, shuffled=True, fixture="table",
                        place_max_rad=0.0, move_s=20.0)
    noise = NoiseSpec(odr_hz=125.0, n=200, density_g=np.array(density), nu=None,
                      vibration=None, raw_lsb_g=None)
    thermal = dataclasses.replace(case.thermal, channel_lsb_c=0.01)
    return dataclasses.replace(case, protocol=protocol, noise=noise, thermal=thermal)


def _means(rows):
    return np.array([[r["ax"], r["ay"], r["az"]] for r in rows])


def test_hysteresis_flips_sign_between_the_legs_at_the_same_temperature():
    # −40 (cooled to from 20 °C), 20 heating, 60, 20 cooling, −40: 20 °C on both legs
    case = _case(11, (-40.0, 20.0, 60.0, 20.0, -40.0))
    drawn, info = draw_effect("thermal_hysteresis", case, 2.0)
    assert drawn.case.protocol.setpoints_c == case.protocol.setpoints_c  # random: kept
    null, eff = simulate(drawn.case), simulate(drawn.case, drawn)
    added = _means(eff) - _means(null)  # the same draws: only the effect differs
    steps = np.array([r["step"] for r in null])
    up, down = added[steps == 1], added[steps == 3]
    # persists through the plateau: one value per axis on each leg
    np.testing.assert_allclose(up, np.broadcast_to(up[0], up.shape), atol=1e-12)
    np.testing.assert_allclose(down, -up, atol=1e-12)
    assert np.all(np.abs(up[0]) > 0.0)
    np.testing.assert_allclose(added[steps == 0], down, atol=1e-12)  # reached by cooling
    # 2 × the detectable size: noncentrality (2·z_0.995)² after the base model, against
    # the drawn noise (the temperature channel's included)
    lam = noncentrality(null, added, channel=channel_noise(drawn.case, null))
    np.testing.assert_allclose(lam, (2.0 * norm.ppf(0.995)) ** 2, rtol=1e-6)


def test_a_one_way_staircase_is_given_legs_and_zigzag_alternates():
    assert zigzag((-40.0, -15.0, 10.0, 35.0, 60.0)) == (-40.0, 10.0, -15.0, 60.0, 35.0)
    case = _case(12, (-40.0, -15.0, 10.0, 35.0, 60.0), order="up")
    drawn, info = draw_effect("thermal_hysteresis", case, 2.0)
    assert drawn.case.protocol.order in ("updown", "zigzag") and info["changed"]
    assert len(set(np.sign(np.diff(drawn.case.protocol.setpoints_c)))) == 2


def test_the_detectable_size_scales_with_the_drawn_noise():
    sp = (-40.0, -15.0, 10.0, 35.0, 60.0)
    lo, hi = _case(13, sp), _case(13, sp, density=(40e-6, 50e-6, 60e-6))
    rows_lo = simulate(lo)
    t = np.array([r["t_s"] for r in rows_lo]) / 3600.0
    pattern = np.c_[t, -t, 0.5 * t]  # a drift
    base = detectable_amplitude(rows_lo, pattern)
    # the same rows with every drawn sd doubled: exactly twice the amplitude
    doubled = [r | {f"sd_{a}": 2.0 * r[f"sd_{a}"] for a in "xyz"} for r in rows_lo]
    np.testing.assert_allclose(detectable_amplitude(doubled, pattern) / base, 2.0, rtol=1e-9)
    # a case drawn at twice the noise density (its soaks, so its times, differ a little)
    drift_hi, info_hi = draw_effect("bias_drift", hi, 1.0)
    drift_lo, info_lo = draw_effect("bias_drift", lo, 1.0)
    assert drift_hi.params["w"].tolist() == drift_lo.params["w"].tolist()
    np.testing.assert_allclose(info_hi["detectable"] / info_lo["detectable"], 2.0, rtol=0.01)


def test_a_step_of_the_temperature_channel_moves_the_channel_not_the_output():
    case = _case(14, (-40.0, -15.0, 10.0, 35.0, 60.0), order="up")
    drawn, info = draw_effect("temperature_sensor", case, 2.0)
    k, delta = drawn.params["from_step"], drawn.amplitude
    null, eff = simulate(drawn.case), simulate(drawn.case, drawn)
    np.testing.assert_array_equal(_means(eff), _means(null))
    moved = np.array([a["sensor_c"] - b["sensor_c"] for a, b in zip(eff, null, strict=True)])
    steps = np.array([r["step"] for r in null])
    assert 2 <= k <= 3 and delta > 0
    np.testing.assert_allclose(moved[steps < k], 0.0, atol=0.006)
    np.testing.assert_allclose(moved[steps >= k], delta, atol=0.006)  # LSB 0.01 °C


def test_the_channel_rounding_counts_only_where_its_noise_does_not_dither_it():
    q = 0.5
    np.testing.assert_allclose(rounding_variance(q, 0.0), q**2 / 12, rtol=0.01)
    assert rounding_variance(q, 0.1 * q) > 0.3 * q**2 / 12
    assert rounding_variance(q, 0.6 * q) < 1e-6 * q**2
