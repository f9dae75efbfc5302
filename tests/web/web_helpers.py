"""Helpers of the browser tests: the live service, Chromium or skip, sign-in, campaigns."""

from __future__ import annotations

import json
import shutil
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from typing import Any

import pytest


@dataclass
class LiveService:
    url: str
    tokens: dict[str, str]
    session_factory: Any = None

    def call(self, method: str, path: str, body: Any = None, role: str = "operator") -> Any:
        """The REST API with a bearer token: the JSON answer (HTTPError on 4xx/5xx)."""
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(
            self.url + path, data=data, method=method,
            headers={"Authorization": f"Bearer {self.tokens[role]}",
                     "Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=30) as response:
            raw = response.read()
        return json.loads(raw) if raw else None

    def start_campaign(self, sensor: str | None, **spec: Any) -> dict[str, Any]:
        """A short campaign on the sim rig (``sensor`` None: give ``sensors=[...]``)."""
        body = {"rig": "sim", "setpoints_c": [20, 35, 50], "soak_min": 10,
                "positions": "table1", "samples_per_position": 20, **spec}
        if sensor is not None:
            body["sensor"] = sensor
        return self.call("POST", "/api/v1/campaigns", body)

    def wait_campaign(self, campaign_id: int, *states: str, cpu_s: float = 60,
                      wall_s: float = 900) -> dict:
        """Until the campaign is in one of ``states``.

        The budget is this process's CPU time: the service, its engine and the fitting
        phase run in it (threads), and a fit is CPU work that a loaded machine stretches
        in wall time (a ramp campaign's continuous fit outlasted 60 s of wall under load),
        while the rig's own time runs on the wall clock whatever the load. ``wall_s`` only
        bounds a hang.
        """
        cpu_deadline = time.process_time() + cpu_s
        wall_deadline = time.monotonic() + wall_s
        while True:
            c = self.call("GET", f"/api/v1/campaigns/{campaign_id}")
            if c["state"] in states:
                return c
            assert time.process_time() < cpu_deadline and time.monotonic() < wall_deadline, (
                f"campaign {campaign_id} still {c['state']} after {cpu_s:g} CPU-s or "
                f"{wall_s:g} s: {c['progress']}, action {c['requested_action']}, "
                f"error {c['error']}")
            time.sleep(0.1)

    def abort(self, campaign_id: int | str) -> None:
        """Abort and wait until the rig is free again (an abort acts at the runner's next
        safe point; the next test may want the rig)."""
        self.call("POST", f"/api/v1/campaigns/{campaign_id}/abort")
        self.wait_campaign(int(campaign_id), "aborted", "completed", "failed")


def chromium_or_skip() -> str:
    """Debian's chromium and the playwright package, or skip with the reason."""
    found = shutil.which("chromium")  # Debian's package puts it on PATH
    if not found:
        pytest.skip("no Chromium on PATH (apt-get install chromium; .ci/run installs it)")
    pytest.importorskip("playwright.sync_api", reason="pip install playwright (test extra)")
    return found


def sign_in(page: Any, service: LiveService, role: str) -> None:
    page.goto(service.url + "/")
    page.fill("#token", service.tokens[role])
    page.click("#signin button")
    page.wait_for_selector("#nav:not([hidden])")
    page.wait_for_selector("#main h2:text('Campaigns')")  # the first view is drawn
    assert f"({role})" in page.inner_text("#who")


def open_view(page: Any, service: LiveService, fragment: str, ready: str) -> None:
    """Go to a view (``#/...``) and wait for its ``ready`` selector."""
    page.goto(f"{service.url}/{fragment}")
    page.wait_for_selector(ready)


def table_rows(page: Any, selector: str) -> list[list[str]]:
    """The data cells (td) of a table's rows that have any (header rows left out)."""
    return page.eval_on_selector(
        selector,
        "(t) => Array.from(t.querySelectorAll('tr')).filter((r) => r.querySelector('td'))"
        ".map((r) => Array.from(r.querySelectorAll('td')).map((c) => c.innerText.trim()))")
