"""Each catalogue effect changes the output as its compact model says, and only where it should
(docs/effects.md)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from effect_context import ctx_for

from calibration import sfem
from calibration.schedules import cube14, six_position, table1
from simulators import effects as fx
from simulators.campaign_sim import RigPhysics, compressor_vibration, simulate_campaign
from simulators.truth import SensorTruth

# benchmarks/ is a repo directory, not an installed package (pyproject packages.find).
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.blind import detectability  # noqa: E402

RNG = np.random.default_rng(0)


@pytest.fixture
def truth() -> SensorTruth:
    return SensorTruth.adxl355_typical(3)


def test_ideal_raw_is_what_eq1_maps_back_onto_the_reference(truth: SensorTruth) -> None:
    """The twin's sensor reads raw = A(T)⁻¹ f + b(T): Eq. 1 forward at T gives f again."""
    ref, T = cube14(), np.linspace(-40, 60, 14)
    raw = truth.ideal_raw_g(ref, T)
    np.testing.assert_allclose(sfem.forward(truth.params_vector_at(T), raw), ref, atol=1e-14)
    one = np.array([truth.ideal_raw_g(ref[i], T[i])[0] for i in range(14)])
    np.testing.assert_allclose(raw, one, atol=0)
    assert np.max(np.abs(raw - ref)) > 1e-3  # the sensor's errors are visible


def test_hysteresis_follows_direction(truth: SensorTruth) -> None:
    ref = six_position()
    d = np.array([1, -1, 0, 1, -1, 1])
    h = np.array([10e-6, -5e-6, 2e-6])
    out = fx.ThermalHysteresis(h_g=h).raw_delta_g(ctx_for(ref, direction=d), truth, RNG)
    np.testing.assert_allclose(out, d[:, None] * h[None, :])


def test_hysteresis_constant_in_one_way_staircase(truth: SensorTruth) -> None:
    sim = simulate_campaign(truth, (-40, -30, -20, 0, 20), six_position(), soak_min=5,
                            return_truth=True)
    ctx = sim.extra["context"]
    out = fx.ThermalHysteresis(h_g=np.full(3, 1e-5)).raw_delta_g(ctx, truth, RNG)
    later = ctx.step >= 1  # after the first step's direction is fixed (heating)
    np.testing.assert_allclose(out[later], 1e-5)


def test_scale_nonlinearity_formula_and_axis_aligned(truth: SensorTruth) -> None:
    ref = cube14()
    k2, k3 = np.array([1e-4, -2e-4, 3e-4]), np.array([5e-5, 0.0, -1e-4])
    out = fx.ScaleNonlinearity(k2_per_g=k2, k3_per_g2=k3).raw_delta_g(ctx_for(ref), truth, RNG)
    np.testing.assert_allclose(out, k2 * ref**2 + k3 * ref**3)
    # at +1/−1 g on an axis: K3 looks like scale, K2 like bias (effects.md "how a soak hides")
    np.testing.assert_allclose(out[0] - out[1], 2 * k3 * np.array([1, 0, 0]), atol=1e-18)


def test_cross_coupling_zero_at_axis_aligned(truth: SensorTruth) -> None:
    eff = fx.CrossCoupling(k_xy_per_g=1e-4, k_xz_per_g=-2e-4, k_yz_per_g=3e-4)
    np.testing.assert_allclose(eff.raw_delta_g(ctx_for(six_position()), truth, RNG), 0.0)
    d = np.array([[1.0, 1.0, 0.0]]) / np.sqrt(2)
    out = eff.raw_delta_g(ctx_for(d), truth, RNG)[0]
    np.testing.assert_allclose(out, [0.5e-4, 0.5e-4, 0.0])


def test_bias_drift_linear_and_relaxation(truth: SensorTruth) -> None:
    ref = six_position()
    t = np.array([0, 3600, 7200, 36000, 72000, 360000.0])
    eff = fx.BiasDrift(rate_g_per_h=np.array([1e-6, -2e-6, 0.0]), relax_g=np.array([0, 0, 5e-6]),
                       relax_tau_h=10.0)
    out = eff.raw_delta_g(ctx_for(ref, t_s=t), truth, RNG)
    np.testing.assert_allclose(out[:, 0], 1e-6 * t / 3600)
    np.testing.assert_allclose(out[:, 1], -2e-6 * t / 3600)
    np.testing.assert_allclose(out[:, 2], 5e-6 * (1 - np.exp(-t / 36000)))


def test_session_offset_per_session(truth: SensorTruth) -> None:
    s = np.array([0, 0, 1, 1, 2, 2])
    off = np.array([[0, 0, 0], [1e-5, 0, 0], [0, -2e-5, 3e-5]])
    out = fx.SessionOffset(offsets_g=off).raw_delta_g(ctx_for(six_position(), session=s),
                                                      truth, RNG)
    np.testing.assert_allclose(out, off[s])
    with pytest.raises(ValueError):
        fx.SessionOffset(offsets_g=off[:2]).raw_delta_g(ctx_for(six_position(), session=s),
                                                        truth, RNG)


def test_temperature_rate_zero_when_soaked(truth: SensorTruth) -> None:
    k = np.array([1e-4, 2e-4, -1e-4])
    rate = np.array([0, 0, 0.01, -0.02, 0, 0])
    out = fx.TemperatureRate(k_g_per_c_per_s=k).raw_delta_g(
        ctx_for(six_position(), die_rate_c_per_s=rate), truth, RNG)
    np.testing.assert_allclose(out, rate[:, None] * k)


def test_outlier_whole_reading_and_spike(truth: SensorTruth) -> None:
    ctx = ctx_for(six_position())
    out = fx.Outlier(size_g=np.array([1e-3, 0, 0]), rows=(2,)).raw_delta_g(ctx, truth, RNG)
    assert np.count_nonzero(out) == 1 and out[2, 0] == pytest.approx(1e-3)
    spike = fx.Outlier(size_g=np.array([0, 0.1, 0]), rows=(4,), spike_samples=2)
    out = spike.raw_delta_g(ctx, truth, RNG)
    assert out[4, 1] == pytest.approx(0.1 * 2 / 200) and np.count_nonzero(out) == 1
    many = fx.Outlier(size_g=1e-3, probability=0.5).raw_delta_g(ctx_for(table1()), truth,
                                                                np.random.default_rng(1))
    assert 0 < np.count_nonzero(many[:, 0]) < 24


def test_vibration_rectification_needs_vibration(truth: SensorTruth) -> None:
    vib = np.array([0, 0, 1e-3, 1e-3, 2e-3, 0])
    c = np.array([10.0, -5.0, 0.0])
    out = fx.VibrationRectification(c_per_g=c).raw_delta_g(
        ctx_for(six_position(), vib_sd_g=vib), truth, RNG)
    np.testing.assert_allclose(out, vib[:, None] ** 2 * c)


def test_compressor_vibration_per_step(truth: SensorTruth) -> None:
    sp = (-40.0, -10.0, 0.0, 20.0)
    ph = RigPhysics(vib_sd_g_by_step=compressor_vibration(sp, 1e-3))
    sim = simulate_campaign(truth, sp, six_position(), soak_min=1, physics=ph, return_truth=True)
    ctx = sim.extra["context"]
    np.testing.assert_allclose(ctx.vib_sd_g, np.where(ctx.step < 2, 1e-3, 0.0))
    sd = sim.recording.columns["sd_x"]
    assert sd[ctx.step == 0].mean() > 3 * sd[ctx.step == 3].mean()


def test_self_heating_shifts_die_and_sensor_channel(truth: SensorTruth) -> None:
    ctx = ctx_for(six_position())
    eff = fx.SelfHeating(delta_c=2.0)
    np.testing.assert_allclose(eff.temperature_delta_c(ctx, RNG), 2.0)
    expect = truth.ideal_raw_g(ctx.ref_g, ctx.die_c + 2) - truth.ideal_raw_g(
        ctx.ref_g, ctx.die_c)
    np.testing.assert_allclose(eff.raw_delta_g(ctx, truth, RNG), expect)
    warm = fx.SelfHeating(delta_c=2.0, warmup_tau_s=60.0).temperature_delta_c(ctx, RNG)
    assert warm[0] == 0.0 and warm[-1] == pytest.approx(2 * (1 - np.exp(-5)))


def test_temperature_sensor_touches_only_the_channel(truth: SensorTruth) -> None:
    ctx = ctx_for(six_position())
    eff = fx.TemperatureSensor(offset_c=0.5, k2_per_c=1e-3, glitch_c=3.0, glitch_rows=(1,))
    np.testing.assert_allclose(eff.raw_delta_g(ctx, truth, RNG), 0.0)
    d = eff.temperature_delta_c(ctx, RNG)
    np.testing.assert_allclose(d - 0.5 - 1e-3 * (ctx.die_c - 25) ** 2, [0, 3, 0, 0, 0, 0],
                               atol=1e-12)


def test_local_gravity_is_a_common_scale(truth: SensorTruth) -> None:
    ctx = ctx_for(cube14())
    out = fx.LocalGravity(g_local=1.0005).raw_delta_g(ctx, truth, RNG)
    lin = truth.ideal_raw_g(ctx.ref_g, ctx.die_c) - truth.params_vector_at(ctx.die_c)[:,
                                                                                              :3]
    np.testing.assert_allclose(out, 5e-4 * lin, atol=1e-15)


def test_turntable_tilt_is_not_a_sensor_frame_rotation(truth: SensorTruth) -> None:
    tilt = fx.TurntableGeometry(base_tilt_rad=np.array([1e-3, -2e-3]))
    ref = table1()
    ref2 = tilt.true_ref_g(ref)
    np.testing.assert_allclose(np.linalg.norm(ref2, axis=1), 1.0)
    assert np.linalg.norm(ref2 - ref, axis=1).max() == pytest.approx(np.hypot(1e-3, 2e-3), rel=0.05)
    # a constant rotation R would make ref2 = R ref exactly: it does not
    R, *_ = np.linalg.lstsq(ref, ref2, rcond=None)
    assert np.abs(ref @ R - ref2).max() > 1e-4
    zero = fx.TurntableGeometry(base_tilt_rad=np.zeros(2))
    np.testing.assert_allclose(zero.raw_delta_g(ctx_for(ref), truth, RNG), 0.0, atol=1e-15)


def test_lever_arm_and_filter_delay_zero_when_static(truth: SensorTruth) -> None:
    ref = six_position()
    lever, delay = fx.LeverArm(r_m=np.array([0.05, 0.0, 0.0])), fx.FilterDelay(delay_s=0.005)
    for eff in (lever, delay):
        np.testing.assert_allclose(eff.raw_delta_g(ctx_for(ref), truth, RNG), 0.0)
        zero_w = ctx_for(ref, omega_rad_s=np.zeros((6, 3)))
        np.testing.assert_allclose(eff.raw_delta_g(zero_w, truth, RNG), 0.0, atol=1e-15)
    w = np.tile([0.0, 0.0, 2.0], (6, 1))  # 2 rad/s about z
    rot = ctx_for(ref, omega_rad_s=w)
    a_lever = lever.raw_delta_g(rot, truth, RNG)
    assert np.abs(a_lever[:, 0]).max() == pytest.approx(4 * 0.05 / fx.G0_M_S2, rel=0.05)
    a_fwd = delay.raw_delta_g(rot, truth, RNG)
    a_rev = delay.raw_delta_g(ctx_for(ref, omega_rad_s=-w), truth, RNG)
    np.testing.assert_allclose(a_fwd, -a_rev, atol=1e-12)  # sign flips with direction


def test_thermal_lag_is_rig_physics() -> None:
    lag = fx.ThermalLag(tau_s=900.0)
    assert lag.physics(RigPhysics()).die_tau_s == 900.0
    assert lag.COLUMNS == ("chamber_c",)


def test_every_catalogue_id_has_a_class() -> None:
    ids = {"thermal_lag", "thermal_hysteresis", "temperature_rate", "scale_nonlinearity",
           "cross_coupling", "turntable_geometry", "lever_arm", "filter_delay", "bias_drift",
           "session_offset", "self_heating", "vibration_rectification", "temperature_sensor",
           "local_gravity", "outlier"}
    assert set(fx.EFFECT_CLASSES) == ids


def test_effects_flow_through_the_campaign(truth: SensorTruth) -> None:
    sp = (-20.0, 0.0, 20.0)
    a = simulate_campaign(truth, sp, cube14(), soak_min=5, seed=4)
    truth.effects = [fx.Outlier(size_g=np.array([0, 0, 1e-2]), rows=(3,))]
    b = simulate_campaign(truth, sp, cube14(), soak_min=5, seed=4)
    diff = b.raw_g - a.raw_g
    assert diff[3, 2] == pytest.approx(1e-2) and np.count_nonzero(np.abs(diff) > 1e-12) == 1
    assert a.header == b.header  # no column betrays the effect


def test_minimum_detectable_threshold_and_scaling() -> None:
    assert detectability.threshold(1) == pytest.approx(3.40, abs=0.01)
    ref = np.tile(table1(), (5, 1))
    T = np.repeat(np.linspace(-40, 60, 5), 24)
    x = np.zeros_like(ref)
    x[:, 0] = ref[:, 0] ** 2  # K2 on x: partly bias, not all
    sig = np.full(len(ref), 1e-5)
    lam1 = detectability.noncentrality(1e-6 * x, ref, T, sig)
    m = detectability.minimum_detectable(
        lambda k: detectability.noncentrality(k * 1e-6 * x, ref, T, sig))
    assert m == pytest.approx(detectability.threshold(1) / lam1)
    # a pure bias is absorbed: never detectable
    bias = np.tile([1e-6, 0, 0], (len(ref), 1))
    assert detectability.noncentrality(bias, ref, T, sig) < 1e-6
