"""The other views in Chromium: resume, schedules, rigs (and their check), tokens, API docs.

Each test reads what a person would: the rows, the numbers, the words of a refusal.
"""

from __future__ import annotations

from web_helpers import LiveService, open_view, sign_in, table_rows


def test_resume_a_paused_campaign(page, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    c = live_engine_service.start_campaign("SN-RESUME", soak_min=60)
    live_engine_service.call("POST", f"/api/v1/campaigns/{c['id']}/pause")
    sign_in(page, live_engine_service, "operator")
    open_view(page, live_engine_service, f"#/campaigns/{c['id']}", "#resume-btn")
    assert page.inner_text("#state") == "paused"
    page.click("#resume-btn")  # resuming loses nothing: no question asked
    page.wait_for_function(
        "() => ['queued', 'running'].includes(document.querySelector('#state').textContent)")
    assert "state paused → " in page.inner_text("#journal")
    live_engine_service.call("POST", f"/api/v1/campaigns/{c['id']}/abort")


def test_rigs_list_and_check(page, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    sign_in(page, live_engine_service, "operator")
    open_view(page, live_engine_service, "#/rigs", "#rigs td")
    sim = next(r for r in table_rows(page, "#rigs") if r[0] == "sim")
    assert sim[1] in ("idle", "busy") and '"driver"' in sim[2]
    page.click("#rigs tr:has(td:text-is('sim')) button")
    page.wait_for_selector("#rig-check h3", timeout=60_000)
    assert page.inner_text("#rig-check h3") == "Rig sim: every check passed"
    rows = table_rows(page, "#rig-check table")
    assert rows and {r[2] for r in rows} <= {"pass", "skip"}  # skip: a move not asked for
    assert any(r[2] == "pass" and r[0] == "chamber" for r in rows), rows


def test_api_docs_render_with_no_internet(browser, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    """Swagger UI and ReDoc render while every request to another host is refused."""
    base = live_engine_service.url
    refused: list[str] = []

    def offline(route) -> None:  # type: ignore[no-untyped-def]
        if route.request.url.startswith((base + "/", "data:", "blob:")):
            route.continue_()
        else:
            refused.append(route.request.url)
            route.abort()

    context = browser.new_context()
    try:
        page = context.new_page()
        page.set_default_timeout(30_000)
        page.route("**/*", offline)
        page.goto(base + "/docs")
        page.wait_for_selector(".opblock-tag")
        tags = set(page.locator(".opblock-tag").all_inner_texts())
        assert {"campaigns", "tokens"} <= {t.split("\n")[0].strip() for t in tags}
        page.goto(base + "/redoc")
        page.wait_for_selector(".api-content h2")
        assert page.locator(".api-content h2").count() > 10  # one per operation
    finally:
        context.close()
    assert not refused, f"the docs asked other hosts: {refused}"
