"""A warm-up's stated bias-slope error carries the choice of the degree (issue 20).

Held-out error chooses the degree; on a straight line whose noise looks curved it picks a
quadratic, whose slope at the span's edge then moves with that curvature. The stated
error (model file, report) adds the model-selection term of a model-averaged variance:
for a lower degree the chosen one does not beat beyond the gain's standard error, the
outer product of the two fits' coefficient difference. The gate's own error is the chosen
fit's (test_gate_tempco.py refuses a tilting board by it).
"""

from __future__ import annotations

import numpy as np

from calibration import gate
from calibration.fitting import fit
from calibration.model_file import dump_model_dict
from calibration.recording import Recording
from calibration.warmup import format_warmup

SLOPE_G_PER_C = 2e-3


def _line(seed: int) -> Recording:
    """z bias 2 mg/°C over 20 → 30 °C, 60 five-second capture means, 2 mg white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(60, dtype=float) * 5.0
    T = 20.0 + 10.0 * t / t[-1]
    z = 1.0 + SLOPE_G_PER_C * (T - 20.0) + rng.normal(0.0, 2e-3, t.size)
    ones = np.ones(t.size)
    return Recording.from_columns({"t_s": t, "sensor_c": T, "ax": 0 * ones, "ay": 0 * ones,
                                   "az": z, "sd_x": 1e-3 * ones, "sd_y": 1e-3 * ones,
                                   "sd_z": 1e-3 * ones, "n": 50.0 * ones})


def test_a_quadratic_chosen_on_a_line_states_the_choices_error():
    rec = _line(11)  # a draw whose noise looks curved: held-out error picks degree 2
    result = fit(rec)
    model = result.model
    assert model.degree == 2
    x = model.x_of(rec.temperature_c())
    z = rec.raw_g[:, 2]
    line = np.polynomial.polynomial.polyfit(x, z, 1)
    quad = np.polynomial.polynomial.polyfit(x, z, 2)
    # one orientation: the drift coefficients are an ordinary polynomial fit in x
    np.testing.assert_allclose(model.coeffs[2, 1:], quad[1:], rtol=1e-9, atol=1e-12)
    # the line is not beaten beyond the gain's error: its difference is the added term
    diff = np.array([line[1] - quad[1], -quad[2]])
    added = model.coeff_cov_choice[2, 1:, 1:] - model.coeff_cov[2, 1:, 1:]
    np.testing.assert_allclose(added, np.outer(diff, diff), rtol=1e-9, atol=1e-15)
    # the model file's standard errors are the choice's
    doc = dump_model_dict(model)
    np.testing.assert_allclose(doc["polynomial"]["stderr"]["bz"][1:],
                               np.sqrt(np.diag(model.coeff_cov_choice[2, 1:, 1:])),
                               rtol=1e-12)
    # the report's slope at the span's hot end: the choice's error, wider than the fit's
    slopes = result.report["bias_slope_ug_per_c"]
    hot = slopes["temperature_c"][2]
    _, own = gate.bias_slope_g_per_c(model, np.array([hot]))
    stated_ug = slopes["bz"]["stderr"][2]
    assert stated_ug > 1.5 * own[2, 0] * 1e6
    assert "bx" not in slopes and "by" not in slopes  # held axes: no slope to state
    text = format_warmup(result.report)
    assert f"bias slope at {slopes['temperature_c'][0]:.2f} /" in text
    assert f"bz {slopes['bz']['value'][0]:+.1f} ± {slopes['bz']['stderr'][0]:.1f}" in text


def test_a_line_chosen_states_its_own_fits_error():
    model = fit(_line(1)).model
    assert model.degree == 1
    np.testing.assert_array_equal(model.coeff_cov_choice[2], model.coeff_cov[2])
    slope, stated = gate.bias_slope_g_per_c(model, np.array([25.0]), with_choice=True)
    assert abs(slope[2, 0] - SLOPE_G_PER_C) < 3 * stated[2, 0]


def test_an_axis_fitted_absolutely_states_no_slope_error_rather_than_zero():
    # z up and z down alternating while the board warms: bz is fitted absolutely (its
    # coefficients carry standard errors only, no covariance), so its slope's error is not
    # known; it is given as null, never as ± 0
    rng = np.random.default_rng(3)
    t = np.arange(120, dtype=float) * 5.0
    T = 20.0 + 10.0 * t / t[-1] + rng.normal(0.0, 0.01, t.size)
    up = np.where((np.arange(t.size) // 4) % 2 == 0, 1.0, -1.0)
    ones = np.ones(t.size)
    rec = Recording.from_columns({
        "t_s": t, "sensor_c": T, "ax": rng.normal(0.0, 2e-4, t.size),
        "ay": rng.normal(0.0, 2e-4, t.size),
        "az": up + 0.01 + SLOPE_G_PER_C * (T - 20.0) + rng.normal(0.0, 2e-4, t.size),
        "sd_x": 1e-3 * ones, "sd_y": 1e-3 * ones, "sd_z": 1e-3 * ones, "n": 50.0 * ones})
    result = fit(rec)
    assert "bz" in result.model.fitted and "bz" in result.report["absolute"]["parameters"]
    bz = result.report["bias_slope_ug_per_c"]["bz"]
    assert bz["stderr"] == [None, None, None]
    assert abs(bz["value"][1] - SLOPE_G_PER_C * 1e6) < 100.0
    assert "(fitted absolutely: its error is the absolute fit's)" in format_warmup(result.report)
