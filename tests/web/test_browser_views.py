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
        "() => ['queued', 'running'].includes(document.querySelector('#state')?.textContent)")
    assert "state paused → " in page.inner_text("#journal")
    live_engine_service.abort(c["id"])


def test_rigs_list_and_check(page, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    sign_in(page, live_engine_service, "operator")
    open_view(page, live_engine_service, "#/rigs", "#rigs td")
    sim = next(r for r in table_rows(page, "#rigs") if r[0] == "sim")
    assert sim[1] == "idle" and '"driver"' in sim[2]  # every earlier campaign has ended
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


def test_schedules_add_refuse_and_remove(page, live_engine_service: LiveService) -> None:  # type: ignore[no-untyped-def]
    sign_in(page, live_engine_service, "operator")
    open_view(page, live_engine_service, "#/schedules", "#main details summary")
    page.click("#main details summary")
    form = "#schedule-form"
    page.fill(f"{form} input[name=cron]", "0 20 * * 1-5")
    page.fill(f"{form} input[name=timezone]", "Europe/Berlin")
    page.fill(f"{form} input[name=sensor]", "SN-NIGHTLY")
    page.fill(f"{form} input[name=setpoints_c]", "20,40")
    page.click(f"{form} button")
    page.wait_for_selector("#schedules td:text-is('sim / SN-NIGHTLY')")
    row = next(r for r in table_rows(page, "#schedules") if r[5] == "sim / SN-NIGHTLY")
    assert row[1] == "cron 0 20 * * 1-5 (Europe/Berlin)"
    assert row[2] != "–" and row[3] == "–" and row[4] == "–"  # next run known, never ran
    # a bad cron is refused in words, and the refusal stays on screen
    page.click("#main details summary")
    page.fill(f"{form} input[name=cron]", "61 25 * * *")
    page.fill(f"{form} input[name=sensor]", "SN-BAD")
    page.click(f"{form} button")
    page.wait_for_selector("#error:not([hidden])")
    assert page.inner_text("#error").startswith("HTTP 422: ")
    assert "cron" in page.inner_text("#error")
    # remove asks first
    asked: list[str] = []
    page.once("dialog", lambda d: (asked.append(d.message), d.dismiss()))
    page.click("#schedules tr:has(td:text-is('sim / SN-NIGHTLY')) button")
    page.wait_for_timeout(200)
    assert page.locator("#schedules td:text-is('sim / SN-NIGHTLY')").count() == 1
    assert asked and asked[0].startswith(f"Remove schedule {row[0]} (sim / SN-NIGHTLY)?")
    page.once("dialog", lambda d: d.accept())
    page.click("#schedules tr:has(td:text-is('sim / SN-NIGHTLY')) button")
    page.wait_for_selector("#schedules td:text-is('sim / SN-NIGHTLY')", state="detached")


def test_tokens_listed_and_revoked_by_an_admin_only(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    created = live_engine_service.call("POST", "/api/v1/tokens",
                                       {"role": "viewer", "name": "lab-pc-7"}, role="admin")
    sign_in(page, live_engine_service, "admin")
    open_view(page, live_engine_service, "#/tokens", "#tokens td")
    rows = {r[0]: r for r in table_rows(page, "#tokens")}
    assert rows[str(created["id"])][1:4] == ["lab-pc-7", "viewer", "active"]
    assert created["token"] not in page.inner_text("#main")  # never shown again
    page.once("dialog", lambda d: d.accept())
    page.click(f"#tokens tr:has(td:text-is('{created['id']}')) button")
    page.wait_for_function(
        "(id) => Array.from(document.querySelectorAll('#tokens tr')).some((r) => "
        "r.cells[0].textContent === String(id) && r.cells[3].textContent === 'revoked')",
        arg=created["id"])
    # the revoked token's sign-in is refused, saying why
    page.click("#signout")
    page.wait_for_selector("#token")
    page.fill("#token", created["token"])
    page.click("#signin button")
    page.wait_for_selector("#error:not([hidden])")
    assert "revoked" in page.inner_text("#error")


def test_a_viewer_sees_no_tokens_and_no_controls(
    page, live_engine_service: LiveService, completed_campaign: dict,  # type: ignore[no-untyped-def]
) -> None:
    sign_in(page, live_engine_service, "viewer")
    assert page.is_hidden("a[href='#/tokens']")
    assert page.locator("#start").count() == 0  # no start form
    open_view(page, live_engine_service, "#/rigs", "#rigs td")
    assert page.locator("#rigs button").count() == 0


def test_a_token_revoked_while_the_page_is_open_signs_it_out_saying_why(
    page, live_engine_service: LiveService,  # type: ignore[no-untyped-def]
) -> None:
    created = live_engine_service.call("POST", "/api/v1/tokens",
                                       {"role": "viewer", "name": "lab-pc-9"}, role="admin")
    page.goto(live_engine_service.url + "/")
    page.fill("#token", created["token"])
    page.click("#signin button")
    page.wait_for_selector("#main h2:text('Campaigns')")
    live_engine_service.call("DELETE", f"/api/v1/tokens/{created['id']}", role="admin")
    page.click("a[href='#/rigs']")
    page.wait_for_selector("#token")  # back on the sign-in form
    assert page.inner_text("#error") == (
        "Signed out: this token has been revoked; ask an admin for a new one.")
    assert page.is_hidden("#nav")
