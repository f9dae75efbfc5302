"""Schedules: ``at`` or ``cron`` (validated), list, delete; 422 and 404 paths."""

from __future__ import annotations

import datetime as dt

from fastapi.testclient import TestClient

CAMPAIGN = {"rig": "sim", "sensor": "SN-0001", "setpoints_c": [-10, 20]}


def test_create_at_and_cron_then_list_and_delete(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    at = client.post(
        "/api/v1/schedules",
        headers=auth["operator"],
        json={"campaign": CAMPAIGN, "at": "2030-01-02T20:00:00+01:00"},
    )
    assert at.status_code == 201, at.text
    assert at.json()["next_run_at"] == "2030-01-02T19:00:00Z"
    cron = client.post(
        "/api/v1/schedules",
        headers=auth["operator"],
        json={"campaign": CAMPAIGN, "cron": "0 20 * * 1-5"},
    )
    assert cron.status_code == 201
    next_run = dt.datetime.fromisoformat(cron.json()["next_run_at"])
    assert next_run > dt.datetime.now(dt.UTC) and next_run.hour == 20 and next_run.weekday() < 5
    assert cron.json()["campaign"]["soak_min"] == 60  # stored with its defaults

    listed = client.get("/api/v1/schedules", headers=auth["viewer"]).json()
    assert [s["id"] for s in listed] == [at.json()["id"], cron.json()["id"]]
    sid = at.json()["id"]
    assert client.delete(f"/api/v1/schedules/{sid}", headers=auth["viewer"]).status_code == 403
    deleted = client.delete(f"/api/v1/schedules/{sid}", headers=auth["operator"])
    assert deleted.status_code == 204 and deleted.content == b""
    assert client.delete(f"/api/v1/schedules/{sid}", headers=auth["operator"]).status_code == 404
    assert len(client.get("/api/v1/schedules", headers=auth["viewer"]).json()) == 1


def test_bad_schedules_are_422_naming_the_field(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    def locs(body: dict) -> list:
        response = client.post("/api/v1/schedules", json=body, headers=auth["operator"])
        assert response.status_code == 422, response.text
        return [e["loc"] for e in response.json()["detail"]]

    assert locs({"campaign": CAMPAIGN, "cron": "61 25 * * *"}) == [["body", "cron"]]
    assert locs({"campaign": CAMPAIGN, "at": "tomorrow evening"}) == [["body", "at"]]
    assert locs({"campaign": CAMPAIGN}) == [["body"]]  # neither at nor cron
    assert locs({"campaign": CAMPAIGN, "cron": "0 20 * * *", "at": "2030-01-01T00:00:00Z"}) == [
        ["body"]
    ]
    hot = {**CAMPAIGN, "setpoints_c": [20, 400]}
    assert locs({"campaign": hot, "cron": "0 20 * * *"}) == [["body", "campaign", "setpoints_c", 1]]


def test_viewer_cannot_create_schedules(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    response = client.post(
        "/api/v1/schedules",
        headers=auth["viewer"],
        json={"campaign": CAMPAIGN, "cron": "0 20 * * *"},
    )
    assert response.status_code == 403


def test_cron_in_the_labs_time_zone(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    from zoneinfo import ZoneInfo

    made = client.post("/api/v1/schedules", headers=auth["operator"],
                       json={"campaign": CAMPAIGN, "cron": "30 21 * * *",
                             "timezone": "America/New_York"})
    assert made.status_code == 201, made.text
    assert made.json()["timezone"] == "America/New_York"
    local = dt.datetime.fromisoformat(made.json()["next_run_at"]).astimezone(
        ZoneInfo("America/New_York"))
    assert (local.hour, local.minute) == (21, 30)

    bad = client.post("/api/v1/schedules", headers=auth["operator"],
                      json={"campaign": CAMPAIGN, "cron": "0 20 * * *", "timezone": "Mars/Olympus"})
    assert bad.status_code == 422
    assert [d["loc"] for d in bad.json()["detail"]] == [["body", "timezone"]]
    with_at = client.post("/api/v1/schedules", headers=auth["operator"],
                          json={"campaign": CAMPAIGN, "at": "2030-01-02T20:00:00+01:00",
                                "timezone": "Europe/Berlin"})
    assert with_at.status_code == 422
