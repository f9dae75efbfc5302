"""Campaigns in Chromium: the list's rows, sign-in refusals, a refusal that stays, the header,
a campaign watched live (ETA, chart, pause and abort asked first) and read after it finished."""

from __future__ import annotations

import re

import pytest
from web_helpers import LiveService, open_view, sign_in, table_rows


def test_the_campaign_list_shows_one_row_per_campaign(
    page, live_engine_service: LiveService, completed_campaign: dict,  # type: ignore[no-untyped-def]
) -> None:
    queued = live_engine_service.start_campaign("SN-LIST", soak_min=30)
    live_engine_service.call("POST", f"/api/v1/campaigns/{queued['id']}/pause")
    sign_in(page, live_engine_service, "viewer")  # lands on the campaigns
    page.wait_for_selector("#campaigns td")
    assert "[object" not in page.inner_text("#main")
    rows = {r[0]: r for r in table_rows(page, "#campaigns")}
    done = rows[str(completed_campaign["id"])]
    assert done[1:4] == ["completed", "sim", "SN-DONE"]
    assert done[4] == "all 3 steps" and done[5] == "100 %"
    paused = rows[str(queued["id"])]
    assert paused[1:4] == ["paused", "sim", "SN-LIST"]
    # a row opens its campaign
    page.click(f"#campaigns a[href='#/campaigns/{queued['id']}']")
    page.wait_for_selector("#facts dd")
    assert page.inner_text("#state") == "paused"
    live_engine_service.abort(queued["id"])


@pytest.mark.parametrize(("kind", "said"), [
    ("unknown", "not known to this service"),
    ("revoked", "has been revoked"),
    ("expired", "has expired"),
])
def test_a_refused_token_says_why(
    page, live_engine_service: LiveService, kind: str, said: str,  # type: ignore[no-untyped-def]
) -> None:
    import datetime as dt

    from service.api.auth import create_token, hash_token
    from service.db.models import ApiToken
    from service.db.session import session_scope

    token = "sct_not-a-token-of-this-service"
    if kind != "unknown":
        with session_scope(live_engine_service.session_factory) as session:
            token = create_token(session, "viewer", f"refused {kind}")
            row = session.query(ApiToken).filter_by(token_hash=hash_token(token)).one()
            past = dt.datetime.now(dt.UTC) - dt.timedelta(minutes=1)
            if kind == "revoked":
                row.revoked_at = past
            else:
                row.expires_at = past
    page.goto(live_engine_service.url + "/")
    page.fill("#token", token)
    page.click("#signin button")
    page.wait_for_selector("#error:not([hidden])")
    assert page.inner_text("#error").startswith("Sign-in refused: ")
    assert said in page.inner_text("#error")
    assert page.is_hidden("#nav")


def test_a_refusal_stays_until_the_next_action(page, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    page.clock.install()  # the page's timers on a clock the test moves (time still flows)
    sign_in(page, live_engine_service, "operator")  # lands on the campaigns
    page.fill("input[name=sensor]", "SN-REFUSED")
    page.fill("input[name=positions]", "sphere1")
    page.click("#start button")
    page.wait_for_selector("#error:not([hidden])")
    refusal = page.inner_text("#error")
    assert refusal.startswith("HTTP 422: body.positions") and "sphere1" in refusal, refusal
    # the list re-reads every 5 s: the refusal must survive it
    reads = page.evaluate("() => window.__listReads")
    page.clock.run_for(5_000)  # the re-read's 5 s, without waiting them on the wall clock
    page.wait_for_function("(n) => window.__listReads > n", arg=reads, timeout=15_000)
    assert page.inner_text("#error") == refusal
    # the next action clears it
    page.fill("input[name=positions]", "table1")
    page.click("#start button")
    page.wait_for_selector("#facts dd")
    assert page.is_hidden("#error")
    live_engine_service.abort(page.url.rsplit("/", 1)[1])


def test_the_header_stays_on_one_line_at_800_px(page, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    page.set_viewport_size({"width": 800, "height": 700})
    sign_in(page, live_engine_service, "admin")  # the admin sees every link
    tops = page.eval_on_selector_all(
        "header > *:not([hidden]), header nav a:not([hidden])",
        "(els) => els.map((e) => Math.round(e.getBoundingClientRect().top + "
        "e.getBoundingClientRect().height / 2))")
    assert len(tops) >= 8 and max(tops) - min(tops) <= 2, tops
    assert page.eval_on_selector("header", "(e) => e.scrollWidth <= e.clientWidth")


def _click_and_answer(page, selector: str, *, accept: bool) -> str:  # type: ignore[no-untyped-def]
    """Click ``selector`` and answer the confirm it opens; its message. Fails at once when the
    click opened none: a handler left waiting would answer the next click's dialog."""
    answered: list[str] = []

    def answer(dialog) -> None:  # type: ignore[no-untyped-def]
        answered.append(dialog.message)
        dialog.accept() if accept else dialog.dismiss()

    page.once("dialog", answer)
    page.click(selector)
    for _ in range(100):  # the dialog's event may follow the click by a few ms
        if answered:
            return answered[0]
        page.wait_for_timeout(50)
    page.remove_listener("dialog", answer)
    raise AssertionError(f"clicking {selector} opened no dialog")


def _wait_state(page, *states: str) -> None:  # type: ignore[no-untyped-def]
    """Until the campaign's state on the page is one of ``states`` (an arrow function: the
    page's CSP forbids eval, which a bare expression would need)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        page.wait_for_function(
            "(states) => states.includes(document.querySelector('#state')?.textContent)",
            arg=list(states))
    except PlaywrightTimeout as exc:  # say what the page shows and what it saw happen
        raise AssertionError(
            f"the page shows {page.inner_text('#state')!r}, not one of {states}; "
            f"its journal, newest first:\n{page.inner_text('#journal')}") from exc


def test_watch_a_campaign_live_pause_and_abort_ask_first(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    sign_in(page, live_engine_service, "operator")
    page.fill("input[name=sensor]", "SN-LIVE")
    # The pause must not race the campaign's end: a pause asked after the last position's
    # checkpoint is never applied (the campaign fits and completes), and a 5-step campaign
    # of predictive soaks ends in ≈ 9 s at 3000× (benchmarks/bench_pause_latency.py). So
    # the chamber ramps at 0.005 °C/min: from the sim chamber's start (23 °C, soaked and
    # charted at once) to 60 °C is ≥ 120 h of rig time, ≥ 148 s: longer than the four
    # 30-s waits this test can make before its pause applies, so a test that gets there
    # finds the campaign running whatever the load. A ramp polls, and so can pause, every
    # soak_poll_s (60 s of rig time). Aborted at the end.
    page.fill("input[name=setpoints_c]", "23,30,40,50,60")
    page.fill("input[name=soak_min]", "60")
    page.fill("input[name=ramp_c_per_min]", "0.005")
    page.fill("input[name=positions]", "table1")
    page.fill("input[name=samples_per_position]", "20")
    page.click("#start button")
    page.wait_for_selector("#facts dd")
    page.wait_for_function("() => Number(document.querySelector('#events').textContent) > 2")
    # the ETA is wall time, labelled, with the rig's own time beside it at 3000× (once the
    # engine has published a progress: "unknown" before its first poll)
    page.wait_for_function("() => /^ends in/.test(document.querySelector('#eta').textContent)")
    assert page.inner_text("#facts").count("ETA (wall clock)") == 1
    eta = page.inner_text("#eta")
    span = r"(\d+ s|\d+ min \d\d s|\d+ h \d\d min)"
    match = re.fullmatch(rf"ends in {span} \(rig time {span} at (\d+)×\)", eta)
    assert match, eta
    assert 2700 <= int(match[3]) <= 3300
    # the chart is drawn from the stored history: chamber and setpoint at least
    page.wait_for_selector("#temp-chart polyline[data-series=chamber]")
    assert page.locator("#temp-chart polyline[data-series=setpoint]").count() == 1

    # pause asks first; "no" leaves it running
    _click_and_answer(page, "#pause-btn", accept=False)
    page.wait_for_timeout(300)
    assert page.inner_text("#state") in ("queued", "running")
    asked = [_click_and_answer(page, "#pause-btn", accept=True)]
    _wait_state(page, "paused")
    assert asked and asked[0].startswith("Pause campaign")
    # reloaded mid-campaign, the chart still has everything stored before the page opened
    seen = int(page.get_attribute("#temp-chart polyline[data-series=chamber]", "data-n"))
    page.reload()
    page.wait_for_selector("#temp-chart polyline[data-series=chamber]")
    assert page.inner_text("#state") == "paused"
    assert int(page.get_attribute("#temp-chart polyline[data-series=chamber]", "data-n")) >= seen
    assert page.locator("#temp-chart polyline[data-series='die:SN-LIVE']").count() == 1
    # abort asks too: "no" keeps it paused, "yes" aborts
    _click_and_answer(page, "#abort-btn", accept=False)
    page.wait_for_timeout(300)
    assert page.inner_text("#state") == "paused"
    asked.append(_click_and_answer(page, "#abort-btn", accept=True))
    _wait_state(page, "aborted")
    assert "cannot be resumed" in asked[1]
    journal = page.inner_text("#journal")
    assert "state paused → aborted" in journal  # seen since the reload
    # finished: no stale progress (no ETA, no chamber reading, no buttons)
    assert page.locator("#eta").count() == 0 and page.locator("#chamber").count() == 0
    assert page.inner_text("#step").startswith("stopped at step ")
    assert page.locator("#controls button").count() == 0


def test_a_finished_campaign_read_the_next_morning(
    page, live_engine_service: LiveService, completed_campaign: dict,  # type: ignore[no-untyped-def]
) -> None:
    cid = completed_campaign["id"]
    history = live_engine_service.call("GET", f"/web/campaigns/{cid}/temperatures")
    sign_in(page, live_engine_service, "viewer")
    page.goto(f"{live_engine_service.url}/#/campaigns/{cid}")
    page.reload()  # a fresh page: nothing of it was seen live
    page.wait_for_selector("#temp-chart polyline[data-series=chamber]")
    assert page.inner_text("#state") == "completed"
    assert page.inner_text("#step") == "all 3 steps"
    assert page.inner_text("#result") == f"calibration {completed_campaign['calibration_id']}"
    assert re.search(r"\(took \d+ s wall clock\)", page.inner_text("#finished"))
    assert page.locator("#eta").count() == 0
    # the whole stored history: chamber, setpoint and the die, with legend and axis label
    chart = page.locator("#temp-chart")
    n = {s: int(chart.locator(f"polyline[data-series='{s}']").get_attribute("data-n"))
         for s in ("chamber", "setpoint", "die:SN-DONE")}
    assert n == {"chamber": len(history["chamber_c"]), "setpoint": len(history["setpoint_c"]),
                 "die:SN-DONE": len(history["die_c"]["SN-DONE"])}
    assert n["chamber"] > 60  # 72 measurements and the soak probes
    legend = chart.locator("text.legend").all_text_contents()
    assert legend == ["chamber air (°C)", "setpoint (°C)", "die SN-DONE (°C)"]
    assert "time since the campaign started" in page.text_content("#x-label")
    assert "waiting" not in page.inner_text("#chart-box")
    # the chart spans the three setpoints
    texts = chart.locator("text").all_text_contents()
    ticks = [t for t in texts if t.endswith("°C") and "(" not in t]
    temps = [float(t.split()[0]) for t in ticks]
    assert min(temps) <= 20.5 and max(temps) >= 49.5, ticks


def test_a_two_sensor_campaign_shows_each_die_and_calibration(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    created = live_engine_service.start_campaign(None, sensors=["SN-PAIR-B", "SN-PAIR-A"])
    done = live_engine_service.wait_campaign(created["id"], "completed", "failed", "aborted")
    assert done["state"] == "completed", done["error"]
    sign_in(page, live_engine_service, "viewer")
    open_view(page, live_engine_service, f"#/campaigns/{done['id']}",
              "#temp-chart polyline[data-series=chamber]")
    assert page.inner_text("#result") == "2 of 2 sensors calibrated"
    legend = page.locator("#temp-chart text.legend").all_text_contents()
    assert legend[2:] == ["die SN-PAIR-B (°C)", "die SN-PAIR-A (°C)"]  # the campaign's order
    links = page.locator("#links a").all_inner_texts()
    assert [t for t in links if t.startswith("calibration")] == [
        f"calibration {done['calibration_ids'][s]} ({s})" for s in ("SN-PAIR-B", "SN-PAIR-A")]
    assert "recording SN-PAIR-A (CSV)" in links


def test_a_pause_answer_older_than_the_stream_does_not_stick(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    """The pause's HTTP answer is read right after the request is stored; the runner pauses
    at its next checkpoint and the progress stream shows "paused". On a loaded machine the
    answer ("running, pause requested") can reach the page after that stream event, and the
    stream sends only changes: the page must still end on what the database says. The
    answer is held here until the page has shown "paused"."""
    # a ramp of ≥ 28 s wall (23 → 30 °C at 0.005 °C/min, 3000×): running when paused
    created = live_engine_service.start_campaign(
        "SN-LATE", setpoints_c=[23, 30], soak_min=60, ramp_c_per_min=0.005)
    cid = created["id"]
    sign_in(page, live_engine_service, "operator")
    open_view(page, live_engine_service, f"#/campaigns/{cid}", "#pause-btn")
    _wait_state(page, "running")
    before = live_engine_service.call("GET", f"/api/v1/campaigns/{cid}")
    held: list = []
    page.route(f"**/api/v1/campaigns/{cid}/pause",
               lambda route: held.append((route, route.fetch())))
    page.once("dialog", lambda d: d.accept())
    page.click("#pause-btn")
    _wait_state(page, "paused")  # shown by the stream, the answer still held
    route, answer = held[0]
    late = answer.json()
    if late["state"] == "paused":  # the checkpoint fell between the write and the read
        late = {**before, "requested_action": "pause"}  # the answer read a moment earlier
    assert late["state"] == "running" and late["requested_action"] == "pause"
    route.fulfill(response=answer, json=late)
    # the page shows the late answer (its journal says so), then what the database says
    page.wait_for_function("(line) => document.querySelector('#journal').textContent"
                           ".includes(line)", arg="state paused → running")
    _wait_state(page, "paused")
    assert live_engine_service.call("GET", f"/api/v1/campaigns/{cid}")["state"] == "paused"


def test_the_controls_stay_put_while_progress_streams_in(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    """A progress event redraws the campaign's facts, not its buttons: a button replaced
    under the pointer between mousedown and mouseup never fires its click (an operator's
    pause was lost while a fast rig streamed progress, and the live pause test's dialog
    was then answered by the handler meant for the click before)."""
    created = live_engine_service.start_campaign(
        "SN-STILL", setpoints_c=[23, 30], soak_min=60, ramp_c_per_min=0.005)
    sign_in(page, live_engine_service, "operator")
    open_view(page, live_engine_service, f"#/campaigns/{created['id']}", "#pause-btn")
    _wait_state(page, "running")
    pause = page.query_selector("#pause-btn")
    recording = page.query_selector("#recording")
    seen = int(page.inner_text("#events"))
    page.wait_for_function("(n) => Number(document.querySelector('#events').textContent) >= n",
                           arg=seen + 3)  # three more progress events drawn
    assert pause.evaluate("(b) => b.isConnected") and recording.evaluate("(a) => a.isConnected")
    assert page.inner_text("#controls") == "pause abort"
