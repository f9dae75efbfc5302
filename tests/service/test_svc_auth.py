"""Bearer tokens: 401 missing or unknown, 403 below the needed role, only a hash stored."""

from __future__ import annotations

from fastapi.testclient import TestClient
from sqlalchemy import select

from service.api.auth import hash_token
from service.db.models import ApiToken


def test_missing_token_is_401_with_a_bearer_challenge(client: TestClient) -> None:
    response = client.get("/api/v1/rigs")
    assert response.status_code == 401
    assert response.headers["www-authenticate"] == "Bearer"
    assert "detail" in response.json()


def test_unknown_token_is_401(client: TestClient) -> None:
    response = client.get("/api/v1/rigs", headers={"Authorization": "Bearer sct_nope"})
    assert response.status_code == 401


def test_viewer_reads_but_cannot_start_a_campaign(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.get("/api/v1/campaigns", headers=auth["viewer"]).status_code == 200
    response = client.post(
        "/api/v1/campaigns", json={"rig": "sim", "sensor": "SN-1"}, headers=auth["viewer"]
    )
    assert response.status_code == 403
    assert "operator" in response.json()["detail"]


def test_operator_cannot_add_rigs_or_tokens_admin_can(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    rig = {"name": "lab2", "chamber": {"driver": "sim", "range_c": [-40, 120]}}
    assert client.post("/api/v1/rigs", json=rig, headers=auth["operator"]).status_code == 403
    assert client.post("/api/v1/rigs", json=rig, headers=auth["admin"]).status_code == 201
    assert client.post("/api/v1/rigs", json=rig, headers=auth["admin"]).status_code == 409
    body = {"role": "viewer", "name": "dashboard"}
    assert client.post("/api/v1/tokens", json=body, headers=auth["operator"]).status_code == 403
    created = client.post("/api/v1/tokens", json=body, headers=auth["admin"])
    assert created.status_code == 201
    new = {"Authorization": f"Bearer {created.json()['token']}"}
    assert client.get("/api/v1/rigs", headers=new).status_code == 200


def test_only_the_hash_is_stored(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    token = auth["viewer"]["Authorization"].removeprefix("Bearer ")
    with sf() as session:
        stored = session.scalars(select(ApiToken.token_hash)).all()
    assert hash_token(token) in stored
    assert token not in stored and all(token not in h for h in stored)


def test_openapi_describes_the_bearer_scheme_and_every_contract_path(client: TestClient) -> None:
    doc = client.get("/openapi.json").json()
    assert doc["components"]["securitySchemes"]["HTTPBearer"]["scheme"] == "bearer"
    for path in (
        "/api/v1/rigs", "/api/v1/campaigns", "/api/v1/campaigns/{campaign_id}",
        "/api/v1/campaigns/{campaign_id}/pause", "/api/v1/campaigns/{campaign_id}/resume",
        "/api/v1/campaigns/{campaign_id}/abort", "/api/v1/campaigns/{campaign_id}/recording.csv",
        "/api/v1/campaigns/{campaign_id}/events", "/api/v1/sensors/{serial}/calibrations",
        "/api/v1/calibrations/{calibration_id}", "/api/v1/sensors/{serial}/coefficients",
        "/api/v1/schedules", "/api/v1/schedules/{schedule_id}", "/api/v1/health",
    ):  # fmt: skip
        assert path in doc["paths"], path
    assert "security" in doc["paths"]["/api/v1/rigs"]["get"]
    assert "security" not in doc["paths"]["/api/v1/health"]["get"]


# --- token list, revoke, expiry, last use (issue 13) -----------------------------------


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_admin_lists_tokens_without_their_secrets(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.get("/api/v1/tokens", headers=auth["operator"]).status_code == 403
    listed = client.get("/api/v1/tokens", headers=auth["admin"])
    assert listed.status_code == 200
    rows = listed.json()
    assert {r["role"] for r in rows} == {"viewer", "operator", "admin"}
    assert all(r["status"] == "active" and r["revoked_at"] is None for r in rows)
    secrets = [h["Authorization"].removeprefix("Bearer ") for h in auth.values()]
    assert not any(s in listed.text for s in secrets)
    assert not any(hash_token(s) in listed.text for s in secrets)


def test_a_revoked_token_gets_401_on_its_next_request(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    created = client.post("/api/v1/tokens", json={"role": "operator"}, headers=auth["admin"])
    token_id, token = created.json()["id"], created.json()["token"]
    assert client.get("/api/v1/rigs", headers=_bearer(token)).status_code == 200
    assert client.delete(f"/api/v1/tokens/{token_id}", headers=auth["operator"]).status_code == 403
    assert client.delete(f"/api/v1/tokens/{token_id}", headers=auth["admin"]).status_code == 204
    response = client.get("/api/v1/rigs", headers=_bearer(token))
    assert response.status_code == 401
    assert response.json()["detail"] == "token revoked"
    assert client.delete(f"/api/v1/tokens/{token_id}", headers=auth["admin"]).status_code == 204
    row = next(r for r in client.get("/api/v1/tokens", headers=auth["admin"]).json()
               if r["id"] == token_id)
    assert row["status"] == "revoked" and row["revoked_at"] is not None


def test_revoking_an_unknown_or_out_of_range_id(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.delete("/api/v1/tokens/999", headers=auth["admin"]).status_code == 404
    assert client.delete(f"/api/v1/tokens/{2**63}", headers=auth["admin"]).status_code == 422


def test_an_expired_token_gets_401(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    import datetime as dt

    body = {"role": "viewer", "expires_days": 1}
    created = client.post("/api/v1/tokens", json=body, headers=auth["admin"]).json()
    assert client.get("/api/v1/rigs", headers=_bearer(created["token"])).status_code == 200
    with sf() as session:  # a day later: move the expiry instead of the clock
        row = session.get(ApiToken, created["id"])
        row.expires_at = dt.datetime.now(dt.UTC) - dt.timedelta(seconds=1)
        session.commit()
    response = client.get("/api/v1/rigs", headers=_bearer(created["token"]))
    assert response.status_code == 401 and response.json()["detail"] == "token expired"
    for bad_days in (0, -1, 3651, True, "30"):
        bad = {"role": "viewer", "expires_days": bad_days}
        response = client.post("/api/v1/tokens", json=bad, headers=auth["admin"])
        assert response.status_code == 422, bad_days


def test_last_used_at_is_written(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    token = auth["viewer"]["Authorization"].removeprefix("Bearer ")
    with sf() as session:
        before = session.scalar(select(ApiToken).where(ApiToken.token_hash == hash_token(token)))
        assert before.last_used_at is None
    assert client.get("/api/v1/rigs", headers=auth["viewer"]).status_code == 200
    with sf() as session:
        after = session.scalar(select(ApiToken).where(ApiToken.token_hash == hash_token(token)))
        assert after.last_used_at is not None
