"""The fleet page in Chromium: a lot of calibrated sensors, the one off its lot flagged in the
table, red in the plot, and named on its own calibration page."""

from __future__ import annotations

import copy

from web_helpers import LiveService, open_view, sign_in, table_rows


def _lot_of_seven(service: LiveService, calibration_id: int) -> int:
    """Seven copies of a real calibration spread like a lot (biases 0.3 mg, gains 500 ppm,
    angles 0.2 mrad, tempcos 5 % apart), the last one's bias x 5 mg further off; returns
    the odd one's calibration id."""
    from service.db.models import Calibration
    from service.db.session import session_scope

    with session_scope(service.session_factory) as session:
        base = session.get(Calibration, calibration_id)
        odd = 0
        for k in range(-3, 4):
            doc = copy.deepcopy(base.model)
            units = doc["polynomial"]["physical_units"]
            for name, c in doc["polynomial"]["physical_coefficients"].items():
                c[0] += {"g": 3e-4, "1": 5e-4, "rad": 2e-4}[units[name][0]] * k
                c[1] *= 1 + 0.05 * k
            if k == 3:
                doc["polynomial"]["physical_coefficients"]["bx"][0] += 5e-3
            row = Calibration(sensor=f"SN-LOT{k + 3}", valid_lo_c=base.valid_lo_c,
                              valid_hi_c=base.valid_hi_c, rmse_ug=base.rmse_ug,
                              model_version=base.model_version, model=doc, report=base.report,
                              provenance={})
            session.add(row)
            session.flush()
            odd = row.id
        return odd


def test_the_fleet_page_flags_the_sensor_off_its_lot(
    page, live_engine_service: LiveService, completed_campaign: dict,  # type: ignore[no-untyped-def]
) -> None:
    odd = _lot_of_seven(live_engine_service, completed_campaign["calibration_id"])
    sign_in(page, live_engine_service, "viewer")
    open_view(page, live_engine_service, "#/fleet", "section.lot")
    heading = page.inner_text("section.lot[data-model=ADXL355] h3")
    assert heading.startswith("ADXL355: ") and heading.endswith(" sensor(s) at 25 °C")
    assert int(heading.split()[1]) >= 8  # the seven and the campaign's own sensor
    flags = table_rows(page, "section.lot[data-model=ADXL355] table.lot-flags")
    ours = [r for r in flags if r[0].startswith("SN-LOT")]  # other tests' sensors may differ
    assert [r[:3] for r in ours] == [["SN-LOT6", str(odd), "bx"]]
    bx = ours
    value_mg, median_mg = (float(bx[0][i].split()[0]) for i in (3, 4))
    assert bx[0][3].endswith(" mg") and 5.0 < value_mg - median_mg < 7.0  # 5 mg + its k = 3
    assert bx[0][5].startswith("+") and float(bx[0][5][1:-1]) > 4
    # the plot: one dot per sensor per parameter, the odd one red
    chart = page.locator("svg[id='z-ADXL355']")
    assert chart.locator("circle[data-name=bx]").count() == int(heading.split()[1])
    red = chart.locator("circle.outlier[data-name=bx]")
    assert "SN-LOT6" in [red.nth(i).get_attribute("data-sensor") for i in range(red.count())]
    assert chart.locator("circle.outlier[data-sensor^='SN-LOT']").count() == 1
    # and its calibration page says so
    page.click(f"section.lot table.lot-flags a[href='#/calibrations/{odd}']")
    page.wait_for_function("() => /lot/.test((document.querySelector('#lot') || {}).textContent)")
    assert page.inner_text("#lot").startswith("OUTSIDE its lot (ADXL355, ")
    assert "bx +" in page.inner_text("#lot")
    own = completed_campaign["calibration_id"]
    open_view(page, live_engine_service, f"#/calibrations/{own}",
              f"#main h2:text-is('Calibration {own}')")
    page.wait_for_function("() => /lot/.test((document.querySelector('#lot') || {}).textContent)")
    assert page.inner_text("#lot").startswith("within ±4σ of its lot (ADXL355, ")
