"""Thermal model (Eq. 8) fits: recovery of known cubics, range handling, modes, degree."""

from __future__ import annotations

import numpy as np
import pytest
import thermal_sim

from calibration import extensions, sfem
from calibration.errors import CalibrationError, NotIdentifiable, OutOfRange
from calibration.recording import Recording
from calibration.temperature_conditioning import condition_temperature
from calibration.thermal import fit_campaign


@pytest.fixture(scope="module")
def campaign() -> tuple:
    return thermal_sim.campaign(seed=3)


@pytest.mark.parametrize("method", ["per_step", "joint"])
def test_recovers_known_cubic_coefficients_within_their_uncertainty(
    campaign: tuple, method: str
) -> None:
    truth, rec = campaign
    model = fit_campaign(rec, method=method).model
    expected = thermal_sim.truth_coeffs_in_x(truth, model.t_centre_c, model.t_scale_c)
    pulls = (model.coeffs - expected) / model.coeff_stderr
    assert model.degree == 3 and model.mode == "reference"
    assert np.all(np.abs(pulls) < 5.0), np.round(pulls, 1)
    # the stated uncertainties are honest, neither hiding nor inflating the error
    assert 0.5 < np.std(pulls) < 1.6


def test_joint_and_per_step_models_agree_and_fit_to_noise(campaign: tuple) -> None:
    _, rec = campaign
    a = fit_campaign(rec, method="per_step")
    b = fit_campaign(rec, method="joint")
    assert b.report["joint_fit"]["success"]
    assert 0.7 < b.report["joint_fit"]["chi2_red"] < 1.3
    T = np.linspace(-40, 60, 21)
    diff = a.model.params_vector_at(T) - b.model.params_vector_at(T)
    assert np.max(np.abs(diff[:, sfem.BIAS])) < 20e-6  # g
    for st in b.steps:  # Table 6: polynomial RMSE close to the per-step measurement RMSE
        assert st.rmse_polynomial_ug < 2.0 * st.rmse_measurement_ug + 5.0
        assert st.rmse_before_ug > 100 * st.rmse_polynomial_ug


def test_coefficients_at_is_the_matrix_form_of_compensate(campaign: tuple) -> None:
    _, rec = campaign
    model = fit_campaign(rec).model
    raw = rec.raw_g[:5]
    A, b = model.coefficients_at(12.3)
    np.testing.assert_allclose(model.compensate(raw, np.full(5, 12.3)), (raw - b) @ A.T,
                               atol=1e-14)
    np.testing.assert_allclose(model.params_at(12.3).matrix(), A)


def test_out_of_range_is_refused_unless_extrapolating(campaign: tuple) -> None:
    _, rec = campaign
    model = fit_campaign(rec).model
    lo, hi = model.valid_c
    assert lo < -40 < 60 < hi < 62
    with pytest.raises(OutOfRange) as info:
        model.coefficients_at(hi + 5)
    assert "outside the calibrated range" in str(info.value)
    with pytest.raises(OutOfRange):
        model.compensate(np.ones((2, 3)), np.array([20.0, lo - 0.5]))
    A, _ = model.coefficients_at(hi + 5, extrapolate=True)
    assert A.shape == (3, 3)
    with pytest.raises(CalibrationError, match="no temperature"):
        model.compensate(np.ones((1, 3)), np.array([np.nan]))


def test_degree_is_reduced_when_there_are_few_steps() -> None:
    _, rec = thermal_sim.campaign(seed=5, setpoints=(-20.0, 20.0, 60.0))
    fit = fit_campaign(rec)
    assert fit.model.degree == 2
    assert any("degree reduced from 3 to 2" in n for n in fit.report["notes"])


def test_norm_mode_marks_misalignment_not_identifiable_and_still_compensates_norm() -> None:
    truth, rec = thermal_sim.campaign(seed=7)
    cols = {k: v for k, v in rec.columns.items() if not k.startswith("ref_")}
    fit = fit_campaign(Recording.from_columns(cols))
    m = fit.model
    assert m.mode == "norm"
    assert list(m.identifiable) == [True] * 9 + [False] * 3
    assert np.all(m.coeffs[sfem.MISALIGN] == 0)
    for st in fit.steps:
        assert st.rmse_polynomial_ug < 40.0  # |g| error after, µg (raw: ~20 mg)


def test_recording_without_temperature_is_one_step_at_unknown_temperature() -> None:
    _, rec = thermal_sim.campaign(seed=8, setpoints=(25.0,))
    cols = {k: v for k, v in rec.columns.items()
            if k not in ("sensor_c", "chamber_c", "step", "setpoint_c")}
    cols["chamber_c"] = np.full(len(rec), np.nan)
    fit = fit_campaign(Recording.from_columns(cols))
    m = fit.model
    assert m.valid_c is None and m.degree == 0 and m.temperature_source == "none"
    out = m.compensate(rec.raw_g, np.full(len(rec), np.nan))
    assert np.sqrt(np.mean((out - rec.ref_g) ** 2)) < 30e-6
    m.coefficients_at(float("nan"))  # any temperature is fine for such a model


def test_too_few_positions_is_not_identifiable() -> None:
    _, rec = thermal_sim.campaign(seed=9, setpoints=(25.0,))
    with pytest.raises(NotIdentifiable):
        fit_campaign(rec.subset(np.arange(len(rec)) < 3))


def test_temperature_conditioning_follows_a_creep_and_ignores_an_outlier() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(24) * 15.0
    temp = 25.0 + 0.001 * t + rng.normal(0, 0.05, 24)
    temp[7] += 5.0  # a glitch of the temperature channel
    c = condition_temperature(t, temp, np.zeros(24, int))
    assert c.rejected_rows == 1
    np.testing.assert_allclose(c.row_c, 25.0 + 0.001 * t, atol=0.06)
    assert abs(c.step_c[0] - (25.0 + 0.001 * t.mean())) < 0.03


def test_batched_jacobian_matches_the_single_parameter_one() -> None:
    rng = np.random.default_rng(1)
    P = sfem.identity_vector() + rng.normal(0, 0.05, (6, 12))
    raw = rng.normal(size=(6, 3))
    f, J = sfem.forward_jacobian(P, raw)
    for i in range(6):
        f1, J1 = sfem.forward_jacobian(P[i], raw[i : i + 1])
        np.testing.assert_allclose(f[i], f1[0], atol=1e-14)
        np.testing.assert_allclose(J[i], J1[0], atol=1e-14)


def test_extensions_listed_in_the_model_are_applied_after_the_base_model(
    campaign: tuple,
) -> None:
    _, rec = campaign
    model = fit_campaign(rec).model
    raw, T = rec.raw_g[:4], np.full(4, 20.0)
    base = model.compensate(raw, T)
    extensions.register_extension(
        "test_offset", lambda spec, raw_g, temp_c, cal: cal + spec["offset_g"]
    )
    model.extensions = [{"kind": "test_offset", "offset_g": 1e-3}]
    np.testing.assert_allclose(model.compensate(raw, T), base + 1e-3)
    model.extensions = [{"kind": "no_such_kind"}]
    with pytest.raises(CalibrationError, match="no_such_kind"):
        model.compensate(raw, T)


def test_smoothing_over_time_averages_noise_keeps_ramps_and_plateaus_apart() -> None:
    from calibration.temperature_conditioning import smooth_over_time

    rng = np.random.default_rng(2)
    t = np.arange(200) * 10.0
    true = np.where(t < 1000, 60.0 - 0.01 * t, 20.0)  # a ramp, then a jump to a plateau
    noisy = true + rng.normal(0, 0.3, t.size)
    sm = smooth_over_time(t, noisy, window_s=300.0)
    inner = (np.abs(t - 1000) > 200)
    assert np.std((sm - true)[inner]) < 0.3 / 2.5
    assert np.abs(np.mean((sm - true)[inner])) < 0.05
    assert abs(sm[101] - 20.0) < 0.5  # the first rows after the jump are not pulled up
