"""A ramp campaign in Chromium: the form's method selector and ramp rate, a refusal of a rate
of zero, the ramp's progress in sweeps while it runs and after, and its chart."""

from __future__ import annotations

import csv
import io
import re
import time
import urllib.request

from web_helpers import LiveService, sign_in, table_rows

STEP = re.compile(r"sweep (\d+) of about (\d+)(?:, chamber heading to (-?\d+\.\d) °C)? \(ramp\)")


def _recording_sweeps(service: LiveService, cid: int) -> set[int]:
    """The sweep indices (the recording's ``step`` column) of the stored measurements."""
    request = urllib.request.Request(
        f"{service.url}/api/v1/campaigns/{cid}/recording.csv",
        headers={"Authorization": f"Bearer {service.tokens['viewer']}"})
    with urllib.request.urlopen(request, timeout=30) as response:
        text = response.read().decode()
    rows = csv.DictReader(line for line in io.StringIO(text) if not line.startswith("#"))
    return {int(r["step"]) for r in rows}


def _wait_state(page, *states: str) -> None:  # type: ignore[no-untyped-def]
    page.wait_for_function(
        "(states) => states.includes(document.querySelector('#state')?.textContent)",
        arg=list(states))


def test_the_method_selector_offers_soak_and_ramp_with_the_ramp_rate(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    sign_in(page, live_engine_service, "operator")
    select = page.locator("#start select[name=method]")
    assert select.locator("option").all_text_contents() == ["soak", "ramp"]
    assert select.input_value() == "soak"  # the default, as the API's
    label = page.locator("#start label", has=page.locator("input[name=ramp_c_per_min]"))
    assert label.inner_text().strip() == "Chamber ramp (°C/min)"
    assert page.input_value("#start input[name=ramp_c_per_min]") == "1"
    # a ramp at 0 °C/min (a step) is no ramp: refused with the field, the reason and the fix
    page.fill("input[name=sensor]", "SN-RAMP-0")
    select.select_option("ramp")
    # the rate follows the method's default (the API's: ramp 2 °C/min) until it is typed
    assert page.input_value("#start input[name=ramp_c_per_min]") == "2"
    select.select_option("soak")
    assert page.input_value("#start input[name=ramp_c_per_min]") == "1"
    select.select_option("ramp")
    page.fill("input[name=ramp_c_per_min]", "0")
    page.click("#start button")
    page.wait_for_selector("#error:not([hidden])")
    refusal = page.inner_text("#error")
    assert refusal.startswith("HTTP 422: body.ramp_c_per_min"), refusal
    assert "method 'ramp' needs a controlled ramp" in refusal, refusal
    assert "give the ramp rate, > 0 °C/min" in refusal, refusal
    assert page.inner_text("#main h2") == "Campaigns"  # still the list: nothing started
    started = live_engine_service.call("GET", "/api/v1/campaigns")
    assert not [c for c in started if c["sensor"] == "SN-RAMP-0"]


def test_a_ramp_started_from_the_form_shows_its_sweeps(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    sign_in(page, live_engine_service, "operator")
    page.fill("input[name=sensor]", "SN-RAMP")
    page.select_option("#start select[name=method]", "ramp")
    page.fill("input[name=setpoints_c]", "20,30")
    page.fill("input[name=ramp_c_per_min]", "0.5")  # a slow ramp: time to watch it run
    page.fill("input[name=positions]", "table1")
    page.fill("input[name=samples_per_position]", "20")
    page.click("#start button")
    page.wait_for_selector("#facts dd")
    cid = int(page.url.rsplit("/", 1)[1])
    spec = live_engine_service.call("GET", f"/api/v1/campaigns/{cid}")["spec"]
    assert spec["method"] == "ramp" and spec["ramp_c_per_min"] == 0.5
    assert spec["setpoints_c"] == [20.0, 30.0]

    # running: where it is in sweeps, not setpoint steps; paused, once captures are stored,
    # to read it still
    page.wait_for_function("() => /^sweep \\d+ of about/.test("
                           "document.querySelector('#step').textContent)")
    deadline = time.monotonic() + 60
    while live_engine_service.call("GET", f"/api/v1/campaigns/{cid}")["progress"]["fraction"] == 0:
        assert time.monotonic() < deadline, "no capture stored within 60 s"
        time.sleep(0.05)
    live_engine_service.call("POST", f"/api/v1/campaigns/{cid}/pause")
    _wait_state(page, "paused")
    page.wait_for_function("() => /^sweep/.test(document.querySelector('#step').textContent)")
    progress = live_engine_service.call("GET", f"/api/v1/campaigns/{cid}")["progress"]
    shown = STEP.fullmatch(page.inner_text("#step"))
    assert shown, page.inner_text("#step")
    assert int(shown[1]) == progress["step"] and int(shown[2]) == progress["steps"]
    # the API says it is a ramp and where its chamber is heading; the page shows the same
    assert progress["method"] == "ramp"
    heading = progress["leg_target_c"]
    assert heading is not None and shown[3] == f"{heading:.1f}"
    assert progress["steps"] >= 2  # a ramp up and back sweeps the table more than once
    # the chart, from the stored history (reloaded: no progress event comes while paused):
    # chamber, the ramping setpoint and the die
    page.reload()
    _wait_state(page, "paused")
    for series in ("chamber", "setpoint", "die:SN-RAMP"):
        # attached, not "visible": paused at the first captures a series may be a level
        # line, which a person sees but whose bounding box has no height (Playwright calls
        # it hidden); the line is drawn when it has two points or more
        line = page.wait_for_selector(f"#temp-chart polyline[data-series='{series}']",
                                      state="attached")
        assert line is not None and len((line.get_attribute("points") or "").split()) >= 2

    live_engine_service.call("POST", f"/api/v1/campaigns/{cid}/resume")
    done = live_engine_service.wait_campaign(cid, "completed", "failed", "aborted",
                                             cpu_s=180)
    assert done["state"] == "completed", done.get("error")
    sweeps = _recording_sweeps(live_engine_service, cid)
    page.reload()
    _wait_state(page, "completed")
    # every stored sweep counted, none invented
    assert page.inner_text("#step") == f"all {max(sweeps) + 1} sweeps"
    assert sweeps == set(range(max(sweeps) + 1))
    assert page.inner_text("#result") == f"calibration {done['calibration_id']}"
    assert page.locator("#eta").count() == 0
    # the chart spans the ramp's range: up to 30 °C and back down to 20 °C
    page.wait_for_selector("#temp-chart polyline[data-series=chamber]")
    ticks = [t for t in page.locator("#temp-chart text").all_text_contents()
             if t.endswith("°C") and "(" not in t]
    temps = [float(t.split()[0]) for t in ticks]
    assert min(temps) <= 20.5 and max(temps) >= 29.5, ticks
    # and the list says the same in its row
    page.goto(f"{live_engine_service.url}/#/campaigns")
    page.wait_for_selector("#campaigns td")
    row = {r[0]: r for r in table_rows(page, "#campaigns")}[str(cid)]
    assert row[1:4] == ["completed", "sim", "SN-RAMP"]
    assert row[4] == f"all {max(sweeps) + 1} sweeps" and row[5] == "100 %"
