"""One live service (engine on the ``sim`` rig, fast) and one Chromium for the whole browser suite.

Starting uvicorn and Chromium costs seconds each; every test gets its own
browser context (own cookies) and page instead, and the campaigns it needs
are short accelerated ones on the shared service.
"""

from __future__ import annotations

import urllib.error
from collections.abc import Iterator
from pathlib import Path

import pytest
from web_helpers import LiveService, chromium_or_skip

from tests.live_uvicorn import serve_in_thread

TIMEOUT_MS = 30_000
# 3000× wall: a three-step campaign of 10-min soaks ends in a few seconds.
SIM_SPEED = 3000.0


@pytest.fixture(scope="session")
def live_engine_service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveService]:
    """uvicorn in a thread on a free port, the engine running the sim rig fast."""
    chromium_or_skip()  # before starting anything
    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.session import session_scope

    db = Path(tmp_path_factory.mktemp("browser")) / "browser.db"
    settings = Settings(
        database_url=f"sqlite:///{db}",
        run_engine=True,
        run_scheduler=False,
        sim_speed=SIM_SPEED,
        events_poll_s=0.1,
    )
    app = create_app(settings)
    with serve_in_thread(app) as url:
        tokens = {}
        with session_scope(app.state.session_factory) as session:
            for role in ("viewer", "operator", "admin"):
                tokens[role] = create_token(session, role, f"browser {role}")
        yield LiveService(url=url, tokens=tokens, session_factory=app.state.session_factory)


@pytest.fixture(autouse=True)
def _abort_what_the_test_left(request: pytest.FixtureRequest) -> Iterator[None]:
    """After a test on the live service, abort every campaign it started and left
    unfinished, and wait until the rig is free: a test that fails half-way (its own abort
    never reached) must not leave its campaign holding the sim rig, with the next test's
    campaign queued behind it. Session fixtures' campaigns are made before this runs."""
    if "live_engine_service" not in request.fixturenames:
        yield
        return
    from sqlalchemy import func, select

    from service.db.models import Campaign
    from service.db.session import session_scope
    from service.engine.states import TERMINAL

    service: LiveService = request.getfixturevalue("live_engine_service")
    with session_scope(service.session_factory) as session:
        first_new = (session.scalar(select(func.max(Campaign.id))) or 0) + 1
    yield
    with session_scope(service.session_factory) as session:
        left = session.scalars(select(Campaign.id).where(
            Campaign.id >= first_new, Campaign.state.not_in(TERMINAL))).all()
    for campaign_id in left:
        try:
            service.abort(campaign_id)
        except urllib.error.HTTPError as exc:  # it finished meanwhile: nothing to abort
            if exc.code != 409:
                raise
            service.wait_campaign(campaign_id, *TERMINAL)


# Module scope, not session: Playwright's sync API keeps an event loop running on this thread
# while it is open, and under xdist the worker goes on to other files (whose asyncio tests
# then fail with "Runner.run() cannot be called from a running event loop").
@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    executable = chromium_or_skip()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        yield chromium
        chromium.close()


@pytest.fixture
def page(browser, live_engine_service: LiveService) -> Iterator[object]:  # type: ignore[no-untyped-def]
    """A fresh context (no cookie) and page; fails the test on any script error or on a
    request to another host (the dashboard must work on a lab network with no internet)."""
    context = browser.new_context(viewport={"width": 1200, "height": 900})
    tab = context.new_page()
    tab.set_default_timeout(TIMEOUT_MS)
    errors: list[str] = []
    requested: list[str] = []
    tab.on("pageerror", lambda e: errors.append(str(e)))
    tab.on("request", lambda r: requested.append(r.url))
    yield tab
    context.close()
    assert not errors, errors
    base = live_engine_service.url
    foreign = [u for u in requested if not u.startswith((base + "/", "data:"))]
    assert not foreign, f"the dashboard asked other hosts: {foreign}"


@pytest.fixture(scope="session")
def completed_campaign(live_engine_service: LiveService) -> dict:
    """A short campaign on the sim rig run to its calibration (a few seconds at 3000×).

    Soaked as a lab would: 90 min fixed, 6 time constants of the sim die (15 min), so
    each step is a plateau and the fit is a step fit whatever the load. A 10-min
    predictive soak ends with the die still moving; under load the sweep takes more rig
    time and the steps become continuous rows (calibration/plateaus.py).
    """
    created = live_engine_service.start_campaign("SN-DONE", soak_min=90, stability="fixed")
    return live_engine_service.wait_campaign(created["id"], "completed", "failed", "aborted")


@pytest.fixture(scope="session")
def ramp_campaign(live_engine_service: LiveService) -> dict:
    """A ramp campaign (docs/ramp-campaigns.md) 20 → 60 °C and back to the rig's ambient at
    0.5 °C/min, run to its continuous calibration (about 5 s at 3000×).

    The last leg has no hold and the die lags the air, so the die's cooling leg covers only
    the top of the span; and the engine takes fewer readings per simulated minute when the
    machine is loaded (it lags the 3000× clock). 40 °C of span at 0.5 °C/min leave several
    10-°C bands crossed both ways with ≥ 3 readings each; 20 → 40 °C at 1 °C/min left one at
    most, and none under load. A die rate well above ``LEG_RATE_C_PER_MIN`` (0.2 °C/min)
    keeps the legs' rows from being read as standing."""
    created = live_engine_service.start_campaign(
        "SN-RAMP", method="ramp", setpoints_c=[20, 60], ramp_c_per_min=0.5)
    return live_engine_service.wait_campaign(created["id"], "completed", "failed", "aborted")


@pytest.fixture(scope="session")
def warmup_calibration(live_engine_service: LiveService) -> int:
    """A warm-up calibration (one orientation, the bias change with temperature): no
    campaign makes one (the API refuses a schedule that cannot identify the SFEM), so the
    engine's fitting phase runs on a simulated warm-up log and its row is stored as the
    engine stores one."""
    from service.db.models import Calibration
    from service.db.session import session_scope
    from service.engine.calibrate import calibrate_columns
    from simulators.warmup_log import warmup_log

    rec, _ = warmup_log(seconds=200, rate_hz=100, seed=3)
    row = calibrate_columns({k: list(v) for k, v in rec.columns.items()},
                            {"recording": "warmup.csv"})
    with session_scope(live_engine_service.session_factory) as session:
        cal = Calibration(campaign_id=None, sensor="SN-WARM", **row.columns())
        session.add(cal)
        session.flush()
        return int(cal.id)
