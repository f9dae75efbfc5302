"""Rigs: the embedded ``sim`` rig is seeded at start; ``busy`` follows active campaigns."""

from __future__ import annotations

from fastapi.testclient import TestClient
from svc_helpers import new_campaign, set_campaign


def test_sim_rig_is_seeded_with_its_chamber_range(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    rigs = client.get("/api/v1/rigs", headers=auth["viewer"]).json()
    assert [r["name"] for r in rigs] == ["sim"]
    sim = rigs[0]
    assert set(sim) >= {"name", "chamber", "turntable", "sensors", "busy"}
    assert sim["chamber"]["range_c"] == [-70.0, 180.0] and sim["busy"] is False


def test_seeding_twice_keeps_one_sim_rig(settings) -> None:  # type: ignore[no-untyped-def]
    from service.api.app import create_app

    for _ in range(2):
        with TestClient(create_app(settings)):
            pass
    with TestClient(create_app(settings)) as c:
        from service.api.auth import create_token
        from service.db.session import session_scope

        with session_scope(c.app.state.session_factory) as s:  # type: ignore[attr-defined]
            token = create_token(s, "viewer")
        rigs = c.get("/api/v1/rigs", headers={"Authorization": f"Bearer {token}"}).json()
    assert [r["name"] for r in rigs] == ["sim"]


def test_rig_is_busy_while_a_campaign_runs(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    campaign = new_campaign(client, auth["operator"])
    set_campaign(sf, campaign["id"], state="running")
    rigs = client.get("/api/v1/rigs", headers=auth["viewer"]).json()
    assert rigs[0]["busy"] is True
