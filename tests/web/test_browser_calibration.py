"""A calibration as the lab reads it in Chromium: the numbers that decide pass or fail, the
per-step table, the held-out figure, the figures; a sensor's coefficients at a temperature."""

from __future__ import annotations

import re

from web_helpers import LiveService, open_view, sign_in, table_rows


def _ug(text: str) -> float:
    """'28.9 µg' or '17.71 mg' → µg."""
    value, unit = text.split()
    return float(value) * (1000.0 if unit == "mg" else 1.0)


def test_the_calibration_page_shows_what_decides_pass_or_fail(
    page, live_engine_service: LiveService, completed_campaign: dict,  # type: ignore[no-untyped-def]
) -> None:
    cal_id = completed_campaign["calibration_id"]
    summary = live_engine_service.call("GET", f"/web/calibrations/{cal_id}/summary")
    sign_in(page, live_engine_service, "viewer")
    open_view(page, live_engine_service, f"#/campaigns/{completed_campaign['id']}", "#result")
    page.click("#calibration-link")
    page.wait_for_selector("#cal-facts")
    before, after = _ug(page.inner_text("#rmse-before")), _ug(page.inner_text("#rmse-after"))
    # the sim sensor's raw |g| error is mg, calibrated tens of µg (its noise)
    assert before > 1000 and 5 < after < 200, (before, after)
    assert after == round(summary["rmse_after_ug"], 1)
    lo, hi = summary["valid_c"]
    assert page.inner_text("#valid") == f"{lo:.1f} … {hi:.1f} °C (sensor c)"
    assert page.inner_text("#fitted") == "all 12 SFEM parameters (Eq. 1)"
    assert page.inner_text("#held") == "none"
    assert page.inner_text("#joint").startswith("converged, χ²red ")
    # one row per step: setpoint, die temperature, the three RMSEs, the soak
    rows = table_rows(page, "#cal-steps")
    assert [r[1] for r in rows] == ["20.0 °C", "35.0 °C", "50.0 °C"]
    for row in rows:
        assert row[3] == "24"
        assert _ug(row[4]) > 1000 and _ug(row[6]) < 200
        assert re.fullmatch(r"\d+ min \d\d s|\d+ h \d\d min", row[8]), row
        assert "_" not in row[9] and row[9] != "–"
    assert "polynomial degree reduced from 3 to 2" in page.inner_text("#cal-notes")
    # the held-out figure and the figures come from the refit
    page.wait_for_function("() => /µg|mg/.test(document.querySelector('#loo').textContent)")
    loo = page.inner_text("#loo")
    assert re.match(r"\d+\.\d µg \(in-sample \d+\.\d µg; \d+ spare degrees of freedom", loo), loo
    assert _ug(" ".join(loo.split()[:2])) >= after * 0.8  # held out is no better than fitted
    page.wait_for_function(
        "() => Array.from(document.querySelectorAll('#figures img'))"
        ".every(i => i.complete && i.naturalWidth > 0) && "
        "document.querySelectorAll('#figures img').length >= 2")
    names = page.locator("#figures figcaption").all_inner_texts()
    assert {"norm_error", "parameters_vs_temperature"} <= set(names)
    assert page.get_attribute("#export-c", "href").endswith("/export?format=c")


def test_sensor_calibrations_and_coefficients_in_and_out_of_range(
    page, live_engine_service: LiveService, completed_campaign: dict,  # type: ignore[no-untyped-def]
) -> None:
    cal_id = completed_campaign["calibration_id"]
    summary = live_engine_service.call("GET", f"/web/calibrations/{cal_id}/summary")
    lo, hi = summary["valid_c"]
    sign_in(page, live_engine_service, "viewer")
    open_view(page, live_engine_service, "#/sensors/SN-DONE", "#coef-btn")
    row = next(r for r in table_rows(page, "#main table") if r[0] == str(cal_id))
    assert row[1] == str(completed_campaign["id"])
    assert row[3] == f"{lo:.1f} … {hi:.1f} °C"
    assert row[4] == f"{summary['rmse_after_ug']:.1f} µg"

    page.fill("input[name=temperature_c]", "30")
    page.click("#coef-btn")
    page.wait_for_selector("#coefficients table")
    matrix = table_rows(page, "#coefficients table")
    assert len(matrix) == 3
    diagonal = [float(matrix[i][i]) for i in range(3)]
    assert all(0.95 < d < 1.05 for d in diagonal), matrix  # near unity gain
    assert all(abs(float(r[3])) < 100 for r in matrix)  # bias in mg
    assert page.locator("#extrapolated").count() == 0

    # outside the valid range: refused in this page's words, rounded, with its control
    page.fill("input[name=temperature_c]", "80")
    page.click("#coef-btn")
    page.wait_for_selector("#error:not([hidden])")
    message = page.inner_text("#error")
    assert message == (
        f"80.0 °C is outside calibration {cal_id}'s valid range {lo:.1f} … {hi:.1f} °C, where "
        'the model was not measured. Tick "extrapolate outside the valid range" to evaluate '
        "it there anyway.")
    assert "extrapolate=true" not in message
    assert page.locator("#coefficients table").count() == 0
    page.check("#extrapolate")
    page.click("#coef-btn")
    page.wait_for_selector("#coefficients table")
    assert page.is_hidden("#error")
    assert "outside the valid range" in page.inner_text("#extrapolated")
