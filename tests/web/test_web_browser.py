"""The dashboard in a real browser (Debian's headless Chromium driven by Playwright).

Signs in with a token, starts a short campaign on the ``sim`` rig, watches
progress arrive over SSE (EventSource with the session cookie), pauses and
resumes it, and opens the calibration's figures -- and checks that the page
asked nothing of any host but the service (it must work on a lab network with
no internet). Skipped, with the reason, where Chromium is not installed.
"""

from __future__ import annotations

from web_helpers import LiveService, chromium_or_skip

TIMEOUT_MS = 40_000


def _events(page) -> int:  # type: ignore[no-untyped-def]
    return int(page.inner_text("#events"))


def _wait_state(page, *states: str) -> None:  # type: ignore[no-untyped-def]
    """Until the campaign's state on the page is one of ``states`` (arrow function: the
    page's CSP forbids eval, which a bare expression would need)."""
    page.wait_for_function(
        "(states) => states.includes(document.querySelector('#state').textContent)",
        arg=list(states),
    )


def test_sign_in_start_watch_pause_resume_and_open_figures(
    live_engine_service: LiveService,
) -> None:
    executable = chromium_or_skip()
    from playwright.sync_api import sync_playwright

    base = live_engine_service.url
    requested: list[str] = []
    page_errors: list[str] = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        try:
            page = browser.new_page()
            page.set_default_timeout(TIMEOUT_MS)
            page.on("request", lambda r: requested.append(r.url))
            page.on("pageerror", lambda e: page_errors.append(str(e)))

            page.goto(base + "/")
            page.fill("#token", live_engine_service.tokens["operator"])
            page.click("#signin button")
            page.wait_for_selector("#start")
            assert "(operator)" in page.inner_text("#who")
            assert "sct_" not in page.evaluate("document.cookie")  # HttpOnly: not readable

            page.fill("input[name=sensor]", "SN-BROWSER")
            page.fill("input[name=setpoints_c]", "20,35,50")
            page.fill("input[name=soak_min]", "10")
            page.fill("input[name=positions]", "table1")
            page.fill("input[name=samples_per_position]", "20")
            page.click("#start button")

            # progress moves over SSE: several events, the chart drawn from them
            page.wait_for_selector("#facts")
            page.wait_for_function(
                "() => Number(document.querySelector('#events').textContent) > 2"
            )
            assert page.inner_text("#state") in ("queued", "running")
            assert page.locator("#temp-chart polyline.temp").count() == 1

            page.click("#pause-btn")
            _wait_state(page, "paused")
            paused_at = page.inner_text("#step") + page.inner_text("#position")
            events_paused = _events(page)

            page.click("#resume-btn")
            _wait_state(page, "running", "completed")
            _wait_state(page, "completed")
            journal = page.inner_text("#journal")
            assert "→ paused" in journal
            # a campaign paused before the engine took it goes back to queued, then runs
            assert "paused → running" in journal or "paused → queued" in journal
            assert "soak ended" in journal and "→ completed" in journal
            assert _events(page) > events_paused
            assert page.inner_text("#step") + page.inner_text("#position") != paused_at
            assert page.inner_text("#eta") == "0 min 00 s"

            page.click("#calibration-link")
            page.wait_for_selector("#figures img")
            page.wait_for_function(
                "() => Array.from(document.querySelectorAll('#figures img'))"
                ".every(i => i.complete && i.naturalWidth > 0)"
            )
            names = page.locator("#figures figcaption").all_inner_texts()
            assert {"norm_error", "parameters_vs_temperature"} <= set(names)
            assert page.get_attribute("#export-c", "href").endswith("/export?format=c")

            # The rig's connection check (soakcal rig check) from the rigs page.
            page.click("a[href='#/rigs']")
            page.click("#rigs button")
            page.wait_for_selector("#rig-check h3", timeout=60_000)
            assert "every check passed" in page.inner_text("#rig-check h3")
            assert "pass" in page.inner_text("#rig-check table")
        finally:
            browser.close()
    assert not page_errors, page_errors
    foreign = [u for u in requested if not u.startswith((base + "/", "data:"))]
    assert not foreign, f"the dashboard asked other hosts: {foreign}"


def test_api_docs_render_with_no_internet(live_engine_service: LiveService) -> None:
    """Swagger UI and ReDoc render while every request to another host is refused."""
    executable = chromium_or_skip()
    from playwright.sync_api import sync_playwright

    base = live_engine_service.url
    refused: list[str] = []

    def offline(route) -> None:  # type: ignore[no-untyped-def]
        if route.request.url.startswith((base + "/", "data:", "blob:")):
            route.continue_()
        else:
            refused.append(route.request.url)
            route.abort()

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        try:
            page = browser.new_page()
            page.set_default_timeout(TIMEOUT_MS)
            page.route("**/*", offline)
            page.goto(base + "/docs")
            page.wait_for_selector(".opblock-tag")
            tags = set(page.locator(".opblock-tag").all_inner_texts())
            assert {"campaigns", "tokens"} <= {t.split("\n")[0].strip() for t in tags}
            page.goto(base + "/redoc")
            page.wait_for_selector(".api-content h2")
            assert page.locator(".api-content h2").count() > 10  # one per operation
        finally:
            browser.close()
    assert not refused, f"the docs asked other hosts: {refused}"
