"""One place per effect's physics (docs/diagnosis.md, "Where each effect's physics lives").

The twin's truth effects (``simulators/effects.py``) and the diagnosis effect modules
(``calibration/discrepancy/effects/``) compute the same physical term with the same
function: the twin's output change equals the diagnosis' model-file term and each
shared function follows effects.md's compact model written out by hand here.
"""

from __future__ import annotations

import numpy as np
import pytest
from effect_context import ctx_for as _ctx_for

from calibration.discrepancy.effects.bias_drift import drift_offset_g
from calibration.discrepancy.effects.cross_coupling import CrossCoupling, cross_coupling_g
from calibration.discrepancy.effects.filter_delay import delayed_input_shift_g
from calibration.discrepancy.effects.lever_arm import centripetal_g
from calibration.discrepancy.effects.outlier import spike_mean_fraction
from calibration.discrepancy.effects.scale_nonlinearity import (
    ScaleNonlinearity,
    scale_nonlinearity_g,
)
from calibration.discrepancy.effects.self_heating import warmup_delta_c
from calibration.discrepancy.effects.session_offset import session_offset_g
from calibration.discrepancy.effects.temperature_rate import rate_offset_g
from calibration.discrepancy.effects.temperature_sensor import channel_error_c
from calibration.discrepancy.effects.thermal_hysteresis import (
    ThermalHysteresis,
    hysteresis_offset_g,
)
from calibration.discrepancy.effects.turntable_geometry import tilted_ref_g
from calibration.discrepancy.effects.vibration_rectification import rectified_offset_g
from calibration.schedules import cube14
from simulators import effects as fx
from simulators.truth import Context, SensorTruth

RNG = np.random.default_rng(1)
A_G = cube14()


def ctx_for(ref: np.ndarray, **kw: object) -> Context:
    return _ctx_for(ref, step_s=600.0, **kw)


@pytest.fixture
def truth() -> SensorTruth:
    return SensorTruth.adxl355_typical(4)


def test_cross_coupling_twin_equals_model_file_term(truth: SensorTruth) -> None:
    params = {"k_xy_ug_per_g2": 120.0, "k_xz_ug_per_g2": -40.0, "k_yz_ug_per_g2": 15.0}
    twin = fx.CrossCoupling.from_finding(params).raw_delta_g(ctx_for(A_G), truth, RNG)
    mod = CrossCoupling()
    np.testing.assert_allclose(twin, mod.extension_term_g(mod.extension_fields(params), A_G),
                               rtol=1e-15, atol=0)
    ax, ay, az = A_G.T
    by_hand = np.column_stack([120 * ax * ay - 40 * ax * az, 120 * ax * ay + 15 * ay * az,
                               -40 * ax * az + 15 * ay * az]) * 1e-6
    np.testing.assert_allclose(cross_coupling_g(A_G, [120e-6, -40e-6, 15e-6]), by_hand,
                               rtol=1e-12, atol=1e-22)


def test_scale_nonlinearity_twin_equals_model_file_term(truth: SensorTruth) -> None:
    params = {f"k{n}_{a}_ug_per_g{n}": v for n, vals in ((2, (30.0, -10.0, 5.0)),
                                                         (3, (-8.0, 2.0, 12.0)))
              for a, v in zip("xyz", vals, strict=True)}
    twin = fx.ScaleNonlinearity.from_finding(params).raw_delta_g(ctx_for(A_G), truth, RNG)
    mod = ScaleNonlinearity()
    np.testing.assert_allclose(twin, mod.extension_term_g(mod.extension_fields(params), A_G),
                               rtol=1e-15, atol=0)
    k2, k3 = np.array([30.0, -10.0, 5.0]) * 1e-6, np.array([-8.0, 2.0, 12.0]) * 1e-6
    np.testing.assert_allclose(scale_nonlinearity_g(A_G, k2, k3), k2 * A_G**2 + k3 * A_G**3,
                               rtol=1e-12, atol=1e-22)


def test_hysteresis_twin_equals_model_file_term_on_each_leg(truth: SensorTruth) -> None:
    direction = np.array([0, 1, 1, -1, -1, 1] * 2 + [0, 0])
    params = {"h_x_ug": 7.0, "h_y_ug": -3.0, "h_z_ug": 1.5}
    twin = fx.ThermalHysteresis.from_finding(params).raw_delta_g(
        ctx_for(A_G, direction=direction), truth, RNG)
    mod = ThermalHysteresis()
    spec = mod.extension_fields(params)
    for d in (-1.0, 0.0, 1.0):
        term = mod.extension_term_g({**spec, "direction": d}, A_G)
        np.testing.assert_array_equal(twin[direction == d], term[direction == d])
    np.testing.assert_array_equal(hysteresis_offset_g(-1.0, [7e-6, -3e-6, 1.5e-6]),
                                  [-7e-6, 3e-6, -1.5e-6])


def test_temperature_rate_scales_with_rate_in_any_time_unit(truth: SensorTruth) -> None:
    rate_c_per_s = np.linspace(-0.01, 0.01, A_G.shape[0])
    k_per_c_per_min = np.array([2.0, -1.0, 0.5]) * 1e-6
    per_min = rate_offset_g(rate_c_per_s * 60.0, k_per_c_per_min)
    per_s = rate_offset_g(rate_c_per_s, k_per_c_per_min * 60.0)
    np.testing.assert_allclose(per_min, per_s, rtol=1e-12, atol=1e-24)
    np.testing.assert_allclose(per_s[:, 1], -60e-6 * rate_c_per_s, rtol=1e-12)
    params = {f"k_rate_{a}_ug_per_c_per_min": v for a, v in zip("xyz", (2.0, -1.0, 0.5),
                                                                  strict=True)}
    twin = fx.TemperatureRate.from_finding(params).raw_delta_g(
        ctx_for(A_G, die_rate_c_per_s=rate_c_per_s), truth, RNG)
    np.testing.assert_allclose(twin, per_s, rtol=1e-12, atol=1e-24)


def test_rectification_per_reading_equals_per_axis_when_axes_agree() -> None:
    sd = np.linspace(0.0, 1e-3, 5)
    c = np.array([0.02, -0.01, 0.005])
    one = rectified_offset_g(sd, c)
    per_axis = rectified_offset_g(np.column_stack([sd, sd, sd]), c)
    np.testing.assert_array_equal(one, per_axis)
    np.testing.assert_allclose(one[-1], c * 1e-6, rtol=1e-12)
    assert np.all(one[0] == 0.0)


def test_bias_drift_ramp_and_relaxation() -> None:
    t_h = np.array([0.0, 1.0, 10.0, 100.0])
    ramp = drift_offset_g(t_h, 2e-6)
    np.testing.assert_allclose(ramp[:, 2], 2e-6 * t_h, rtol=1e-15)
    relax = drift_offset_g(t_h, 0.0, [1e-5, 0.0, 0.0], relax_tau_h=10.0)
    np.testing.assert_allclose(relax[2, 0], 1e-5 * (1 - np.exp(-1.0)), rtol=1e-12)
    assert relax[-1, 0] > 0.99995e-5 and np.all(relax[:, 1:] == 0.0)


def test_session_offset_indexes_sessions_and_rejects_missing_ones() -> None:
    off = np.array([[0.0, 0.0, 0.0], [1e-5, -2e-5, 3e-6]])
    out = session_offset_g(np.array([0, 0, 1, 1, 0]), off)
    np.testing.assert_array_equal(out[2], off[1])
    np.testing.assert_array_equal(out[4], off[0])
    with pytest.raises(ValueError, match="sessions"):
        session_offset_g(np.array([0, 2]), off)


def test_self_heating_warmup_curve_is_the_twins_die_offset(truth: SensorTruth) -> None:
    age_s = np.array([-10.0, 0.0, 60.0, 600.0])
    dT = warmup_delta_c(age_s, 2.0, 60.0)
    np.testing.assert_allclose(dT, [0.0, 0.0, 2.0 * (1 - np.exp(-1.0)), 2.0 * (1 - np.exp(-10))],
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(warmup_delta_c(age_s, 2.0, 0.0), np.full(4, 2.0))
    ctx = ctx_for(A_G)  # one session powered on at t = 0
    twin = fx.SelfHeating(delta_c=2.0, warmup_tau_s=900.0).temperature_delta_c(ctx, RNG)
    np.testing.assert_array_equal(twin, warmup_delta_c(ctx.t_s, 2.0, 900.0))


def test_temperature_channel_error_is_offset_plus_curvature_about_25c() -> None:
    die_c = np.array([25.0, 35.0, -15.0])
    np.testing.assert_allclose(channel_error_c(die_c, 0.5, 1e-3), [0.5, 0.6, 2.1], rtol=1e-12)


def test_spike_reaches_the_mean_in_proportion_to_its_samples() -> None:
    n = np.array([200.0, 100.0])
    np.testing.assert_allclose(spike_mean_fraction(5, n), [0.025, 0.05], rtol=1e-15)
    np.testing.assert_array_equal(spike_mean_fraction(None, n), [1.0, 1.0])


def test_centripetal_is_omega_squared_r_toward_the_axis() -> None:
    w = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, -2.0]])
    a = centripetal_g(w, [0.05, 0.0, 0.0])
    np.testing.assert_allclose(a[:, 0], -4.0 * 0.05 / 9.80665, rtol=1e-12)
    np.testing.assert_array_equal(a[0], a[1])  # ∝ ω², blind to the direction
    assert np.all(a[:, 1:] == 0.0)


def test_filter_delay_is_tangential_and_flips_with_direction() -> None:
    ref = np.array([[1.0, 0.0, 0.0]])
    d_plus = delayed_input_shift_g(np.array([[0.0, 0.0, 1.0]]), ref, 0.01)
    d_minus = delayed_input_shift_g(np.array([[0.0, 0.0, -1.0]]), ref, 0.01)
    np.testing.assert_allclose(d_plus, [[0.0, 0.01, 0.0]], atol=1e-18)
    np.testing.assert_array_equal(d_minus, -d_plus)
    assert float(d_plus[0] @ ref[0]) == 0.0


def test_tilted_reference_keeps_magnitude_and_vanishes_without_tilt() -> None:
    np.testing.assert_allclose(tilted_ref_g(A_G, [0.0, 0.0]), A_G, atol=1e-15)
    tilted = tilted_ref_g(A_G, [2e-3, -1e-3])
    np.testing.assert_allclose(np.linalg.norm(tilted, axis=1), np.linalg.norm(A_G, axis=1),
                               rtol=1e-12)
    assert np.max(np.abs(tilted - A_G)) > 1e-3
