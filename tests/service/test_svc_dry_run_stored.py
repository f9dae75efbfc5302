"""The dry run is stored with the campaign at creation: reading a campaign never plans it.

GET, the list, the SSE events (and the dashboard, which reads them) return the stored
prediction; a campaign created before it was stored (migration 0008) gets it computed
once, on first read, and stored.
"""

from __future__ import annotations

import datetime as dt
import json

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

import service.campaigns as campaigns_mod
from service.db.models import Campaign, Schedule
from service.db.session import session_scope
from service.dry_run import predicted_duration_s
from service.engine.spec import EngineSpec
from service.scheduler import Scheduler

CAMPAIGNS = "/api/v1/campaigns"
SCHEDULES = "/api/v1/schedules"
BODY = {"rig": "sim", "sensor": "SN-1", "setpoints_c": [-10, 20], "soak_min": 30,
        "positions": "six", "samples_per_position": 125}


def _row_dry_run(sf: sessionmaker[Session], model: type, row_id: int) -> dict | None:
    with sf() as session:
        return session.scalar(select(model.dry_run).where(model.id == row_id))


def _no_planning(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any dry run from here on fails the test: reads must use what is stored."""
    def refuse(*_a, **_k):  # type: ignore[no-untyped-def]
        raise AssertionError("a read planned the campaign again")
    monkeypatch.setattr(campaigns_mod, "prediction", refuse)
    monkeypatch.setattr(campaigns_mod, "check_campaign", refuse)
    campaigns_mod._prediction_of.cache_clear()


def test_the_prediction_is_stored_at_creation_and_reads_never_plan(
        client: TestClient, auth, sf, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    created = client.post(CAMPAIGNS, json=BODY, headers=auth["operator"])
    assert created.status_code == 201, created.text
    cid, predicted = created.json()["id"], created.json()["predicted_duration_s"]
    expected = predicted_duration_s(EngineSpec.model_validate(
        {k: v for k, v in BODY.items() if k not in ("rig", "sensor")}))
    assert predicted == pytest.approx(expected)
    stored = _row_dry_run(sf, Campaign, cid)
    assert stored is not None and stored["duration_s"] == pytest.approx(expected)
    assert stored["n_steps"] == 2 and stored["n_positions"] == 6 and stored["n_saves"] == 12
    assert stored["ramp_s"] + stored["soak_s"] + stored["positions_s"] == pytest.approx(expected)

    _no_planning(monkeypatch)
    viewer = auth["viewer"]
    assert client.get(f"{CAMPAIGNS}/{cid}", headers=viewer).json()[
        "predicted_duration_s"] == pytest.approx(expected)
    assert client.get(CAMPAIGNS, headers=viewer).json()[0][
        "predicted_duration_s"] == pytest.approx(expected)
    # The stored value is what is served: a row says 1234.5 s, every read says 1234.5 s.
    with session_scope(sf) as session:
        session.execute(update(Campaign).where(Campaign.id == cid)
                        .values(dry_run={**stored, "duration_s": 1234.5}, state="completed"))
    assert client.get(f"{CAMPAIGNS}/{cid}", headers=viewer).json()[
        "predicted_duration_s"] == 1234.5
    events = client.get(f"{CAMPAIGNS}/{cid}/events", headers=viewer).text
    progress = [json.loads(line[5:]) for line in events.splitlines()
                if line.startswith("data:") and '"progress"' in line]
    assert progress and progress[0]["predicted_duration_s"] == 1234.5


def test_a_campaign_stored_without_a_prediction_is_planned_once_then_read(
        client: TestClient, auth, sf, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    cid = client.post(CAMPAIGNS, json=BODY, headers=auth["operator"]).json()["id"]
    expected = _row_dry_run(sf, Campaign, cid)["duration_s"]  # type: ignore[index]
    # as a row created before migration 0008 (and one whose spec no longer validates)
    with session_scope(sf) as session:
        session.execute(update(Campaign).where(Campaign.id == cid).values(dry_run=None))
        old = Campaign(rig="sim", sensor="SN-2", spec={"rig": "sim", "sensor": "SN-2",
                                                       "samples_per_position": 0},
                       state="failed", progress={}, steps_log=[])
        session.add(old)
        session.flush()
        bad_id = old.id
    campaigns_mod._prediction_of.cache_clear()
    calls: list[str] = []
    real = campaigns_mod.prediction
    monkeypatch.setattr(campaigns_mod, "prediction",
                        lambda spec: calls.append(spec.positions) or real(spec))
    viewer = auth["viewer"]
    first = client.get(f"{CAMPAIGNS}/{cid}", headers=viewer).json()["predicted_duration_s"]
    assert first == pytest.approx(expected) and calls == ["six"]
    assert _row_dry_run(sf, Campaign, cid)["duration_s"] == pytest.approx(expected)  # type: ignore[index]
    campaigns_mod._prediction_of.cache_clear()
    again = client.get(f"{CAMPAIGNS}/{cid}", headers=viewer).json()["predicted_duration_s"]
    assert again == pytest.approx(expected) and calls == ["six"]  # stored: not planned again
    # A spec that no longer validates: no prediction, and why, stored once.
    assert client.get(f"{CAMPAIGNS}/{bad_id}", headers=viewer).json()[
        "predicted_duration_s"] is None
    why = _row_dry_run(sf, Campaign, bad_id)
    assert why is not None and why["duration_s"] is None
    assert "not valid any more" in why["why"] and "greater than or equal to 1" in why["why"]


def test_schedules_store_their_prediction_and_fire_it_into_the_campaign(
        client: TestClient, auth, sf, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    at = dt.datetime.now(dt.UTC) + dt.timedelta(hours=1)
    created = client.post(SCHEDULES, json={"campaign": BODY, "at": at.isoformat()},
                          headers=auth["operator"])
    assert created.status_code == 201, created.text
    sid, predicted = created.json()["id"], created.json()["predicted_duration_s"]
    assert _row_dry_run(sf, Schedule, sid)["duration_s"] == pytest.approx(predicted)  # type: ignore[index]
    fired = Scheduler(sf, now=lambda: at + dt.timedelta(seconds=1)).run_due()
    assert len(fired) == 1
    assert _row_dry_run(sf, Campaign, fired[0])["duration_s"] == pytest.approx(predicted)  # type: ignore[index]
    _no_planning(monkeypatch)
    assert client.get(SCHEDULES, headers=auth["viewer"]).json()[0][
        "predicted_duration_s"] == pytest.approx(predicted)
