"""Inputs the audit turned into 500s, refused at the door with a 422 that says where and why.

Each runs on SQLite and PostgreSQL (``clean_db_url``): PostgreSQL cannot store a NUL
character in text or a NaN in JSON, so the same refusal on both keeps one behaviour.
"""

from __future__ import annotations

import json
import time

from fastapi.testclient import TestClient

from service.dry_run import MAX_CAMPAIGN_POSITIONS, MAX_POSITIONS

CAMPAIGNS = "/api/v1/campaigns"
JSON = {"Content-Type": "application/json"}


def _one_error(response) -> dict:  # type: ignore[no-untyped-def, type-arg]
    assert response.status_code == 422, response.text
    (error,) = response.json()["detail"]
    return error


def test_a_nul_character_in_stored_text_is_422_naming_where(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    admin, operator = auth["admin"], auth["operator"]
    token = _one_error(client.post("/api/v1/tokens", json={"role": "viewer", "name": "a\x00b"},
                                   headers=admin))
    assert token["loc"] == ["body", "name"]
    assert token["msg"] == ("text contains a NUL character (\\u0000), which cannot be stored; "
                            "remove it")
    rig = _one_error(client.post(CAMPAIGNS, json={"rig": "s\x00m", "sensor": "SN-1"},
                                 headers=operator))
    assert rig["loc"] == ["body", "rig"]
    nested = _one_error(client.post("/api/v1/schedules", json={
        "campaign": {"rig": "sim\x00", "sensor": "SN-1"}, "cron": "0 20 * * *"},
        headers=operator))
    assert nested["loc"] == ["body", "campaign", "rig"]
    in_key = _one_error(client.post("/api/v1/rigs", json={
        "name": "r1", "chamber": {"driver": "sim", "no\x00te": 1}}, headers=admin))
    assert in_key["loc"] == ["body", "chamber", "no\x00te"]
    path = _one_error(client.get("/api/v1/rigs/a%00b", headers=admin))
    assert path["loc"] == ["path"] and "NUL character (%00)" in path["msg"]
    query = _one_error(client.get(f"{CAMPAIGNS}/1/recording.csv?sensor=S%00", headers=admin))
    assert query["loc"] == ["query", "sensor"]
    # "\\u0000" as text (a backslash, then u0000) is no NUL: an ordinary 201
    ok = client.post("/api/v1/tokens", json={"role": "viewer", "name": "a\\u0000b"},
                     headers=admin)
    assert ok.status_code == 201 and ok.json()["name"] == "a\\u0000b"
    # and the unauthenticated caller learns that first
    assert client.get("/api/v1/rigs/a%00b").status_code == 401


def test_nan_and_infinity_in_a_body_are_422_not_500(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    for token in ("NaN", "Infinity", "-Infinity"):
        body = '{"rig": "sim", "sensor": "SN-1", "soak_min": ' + token + '}'
        error = _one_error(client.post(CAMPAIGNS, content=body,
                                       headers={**auth["operator"], **JSON}))
        assert error["msg"] == f"{token} is not a JSON number; give a finite number"
    in_rig = '{"name": "r2", "chamber": {"driver": "sim", "range_c": [NaN, 60]}}'
    assert client.post("/api/v1/rigs", content=in_rig,
                       headers={**auth["admin"], **JSON}).status_code == 422
    # a string that merely contains the letters is accepted
    ok = client.post("/api/v1/tokens", json={"role": "viewer", "name": "NaNo Infinity"},
                     headers=auth["admin"])
    assert ok.status_code == 201


def test_denormal_tuning_values_are_422_naming_the_field(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    for field in ("expected_sd_g", "tempco_ug_per_c", "drift_budget"):
        error = _one_error(client.post(CAMPAIGNS, json={
            "rig": "sim", "sensor": "SN-1", field: 5e-324}, headers=auth["operator"]))
        assert error["loc"] == ["body", field]
        assert "greater than or equal to" in error["msg"]


def test_a_soak_window_upside_down_is_422(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    error = _one_error(client.post(CAMPAIGNS, json={
        "rig": "sim", "sensor": "SN-1", "min_soak_min": 100, "max_soak_min": 10},
        headers=auth["operator"]))
    assert "min_soak_min 100 is above max_soak_min 10" in error["msg"]
    # the defaults count too: max_soak_min defaults to 2 × soak_min = 60
    error = _one_error(client.post(CAMPAIGNS, json={
        "rig": "sim", "sensor": "SN-1", "soak_min": 30, "min_soak_min": 90},
        headers=auth["operator"]))
    assert "min_soak_min 90 is above max_soak_min 60" in error["msg"]


def test_a_schedule_too_large_to_plan_is_refused_quickly_naming_the_limit(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    for positions in ("sphere5000", "sphere5000+sphere5000", f"sphere{MAX_POSITIONS + 1}"):
        start = time.monotonic()
        error = _one_error(client.post(CAMPAIGNS, json={
            "rig": "sim", "sensor": "SN-1", "positions": positions}, headers=auth["operator"]))
        assert time.monotonic() - start < 5.0  # refused before anything is built
        assert error["loc"] == ["body", "positions"]
        assert f"more than the {MAX_POSITIONS} per step" in error["msg"]
    many_steps = [float(-40 + (i % 100)) for i in range(200)]
    error = _one_error(client.post(CAMPAIGNS, json={
        "rig": "sim", "sensor": "SN-1", "positions": "table1", "setpoints_c": many_steps},
        headers=auth["operator"]))
    assert error["msg"].startswith("200 setpoints × 24 positions is 4800 positions, more than "
                                   f"the {MAX_CAMPAIGN_POSITIONS}")


def test_sign_in_from_another_origin_is_403(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    token = auth["viewer"]["Authorization"].split()[1]
    csrf = {"X-Soakcal-CSRF": "1"}
    foreign = client.post("/web/session", json={"token": token},
                          headers={**csrf, "Origin": "https://evil.example"})
    assert foreign.status_code == 403
    assert foreign.json()["detail"] == "cross-origin request from https://evil.example"
    assert "set-cookie" not in foreign.headers
    own = client.post("/web/session", json={"token": token},
                      headers={**csrf, "Origin": "http://testserver"})
    assert own.status_code == 200 and own.json()["role"] == "viewer"


def test_the_campaign_list_pages_newest_first(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    ids = [client.post(CAMPAIGNS, json={"rig": "sim", "sensor": f"SN-{i}", "positions": "six"},
                       headers=auth["operator"]).json()["id"] for i in range(5)]
    viewer = auth["viewer"]
    everything = client.get(CAMPAIGNS, headers=viewer)
    assert [c["id"] for c in everything.json()] == ids[::-1]
    assert everything.headers["x-total-count"] == "5"
    page = client.get(CAMPAIGNS, params={"limit": 2, "offset": 1}, headers=viewer)
    assert [c["id"] for c in page.json()] == [ids[3], ids[2]]
    assert page.headers["x-total-count"] == "5"
    assert client.get(CAMPAIGNS, params={"limit": 2, "offset": 4},
                      headers=viewer).json()[0]["sensor"] == "SN-0"
    queued = client.get(CAMPAIGNS, params={"state": "running", "limit": 3}, headers=viewer)
    assert queued.json() == [] and queued.headers["x-total-count"] == "0"
    too_many = _one_error(client.get(CAMPAIGNS, params={"limit": 5000}, headers=viewer))
    assert too_many["loc"] == ["query", "limit"]
    typo = _one_error(client.get(CAMPAIGNS, params={"limt": 2}, headers=viewer))
    assert typo["msg"] == "unknown query parameter 'limt'; see docs/api.md"
    # the stored prediction is the same in the list as at creation
    first = json.loads(everything.content)[-1]
    assert first["predicted_duration_s"] == client.get(
        f"{CAMPAIGNS}/{ids[0]}", headers=viewer).json()["predicted_duration_s"] > 0
