"""Campaigns: defaults, 422s naming the field, list and filter, 404, controls and 409s."""

from __future__ import annotations

from fastapi.testclient import TestClient
from svc_helpers import new_campaign, set_campaign


def test_create_fills_the_contract_defaults(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    campaign = new_campaign(client, auth["operator"])
    assert campaign["state"] == "queued" and campaign["rig"] == "sim"
    assert campaign["spec"]["setpoints_c"] == [-40, -30, -20, -10, 0, 10, 20, 30, 40, 50, 60]
    assert campaign["spec"]["soak_min"] == 60 and campaign["spec"]["positions"] == "table1"
    assert campaign["spec"]["samples_per_position"] == 200
    assert set(campaign) >= {
        "id",
        "rig",
        "sensor",
        "state",
        "created_at",
        "started_at",
        "finished_at",
        "progress",
        "calibration_id",
        "error",
    }
    progress = campaign["progress"]
    assert set(progress) == {
        "step",
        "steps",
        "phase",
        "position",
        "positions",
        "fraction",
        "chamber_c",
        "setpoint_c",
        "eta_s",
        "eta_wall_s",
        "method",
        "leg_target_c",
    }
    assert (progress["steps"], progress["positions"], progress["setpoint_c"]) == (11, 24, -40)
    assert (progress["method"], progress["leg_target_c"]) == ("soak", None)


def test_a_second_campaign_on_a_busy_rig_waits_queued(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    first = new_campaign(client, auth["operator"])
    set_campaign(sf, first["id"], state="running")
    second = new_campaign(client, auth["operator"], sensor="SN-0002")
    assert second["state"] == "queued"


def _detail_locs(response) -> list[list]:  # type: ignore[no-untyped-def]
    assert response.status_code == 422, response.text
    return [entry["loc"] for entry in response.json()["detail"]]


def test_setpoints_outside_the_chamber_range_are_422_naming_them(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    response = client.post(
        "/api/v1/campaigns",
        json={"rig": "sim", "sensor": "SN-1", "setpoints_c": [-40, 200, -75]},
        headers=auth["operator"],
    )
    assert _detail_locs(response) == [["body", "setpoints_c", 1], ["body", "setpoints_c", 2]]
    assert "chamber range" in response.json()["detail"][0]["msg"]


def test_bad_bodies_are_422_naming_the_field(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    post = lambda body: client.post("/api/v1/campaigns", json=body, headers=auth["operator"])  # noqa: E731
    assert ["body", "sensor"] in _detail_locs(post({"rig": "sim"}))
    assert _detail_locs(post({"rig": "nope", "sensor": "SN-1"})) == [["body", "rig"]]
    assert _detail_locs(post({"rig": "sim", "sensor": "S", "soak_min": -1})) == [
        ["body", "soak_min"]
    ]
    assert _detail_locs(post({"rig": "sim", "sensor": "S", "positions": "hexagon"})) == [
        ["body", "positions"]
    ]
    response = post({"rig": "sim", "sensor": "S", "soak": 5})
    assert _detail_locs(response) and "soak" in response.json()["detail"][0]["msg"]


def test_engine_tuning_keys_pass_through_to_the_spec(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    campaign = new_campaign(client, auth["operator"], ramp_c_per_min=3.0)
    assert campaign["spec"]["ramp_c_per_min"] == 3.0


def test_get_list_and_filter_by_state(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    a = new_campaign(client, auth["operator"])
    b = new_campaign(client, auth["operator"], sensor="SN-0002")
    set_campaign(sf, b["id"], state="running", progress={"chamber_c": -12.5, "eta_s": 300.0})
    got = client.get(f"/api/v1/campaigns/{b['id']}", headers=auth["viewer"]).json()
    assert got["state"] == "running" and got["progress"]["chamber_c"] == -12.5
    running = client.get("/api/v1/campaigns?state=running", headers=auth["viewer"]).json()
    assert [c["id"] for c in running] == [b["id"]]
    everything = client.get("/api/v1/campaigns", headers=auth["viewer"]).json()
    assert {c["id"] for c in everything} == {a["id"], b["id"]}
    bad = client.get("/api/v1/campaigns?state=sleeping", headers=auth["viewer"])
    assert _detail_locs(bad) == [["query", "state"]]


def test_unknown_campaign_is_404_everywhere(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    for path in ("", "/recording.csv", "/events"):
        assert client.get(f"/api/v1/campaigns/999{path}", headers=auth["viewer"]).status_code == 404
    for action in ("pause", "resume", "abort"):
        response = client.post(f"/api/v1/campaigns/999/{action}", headers=auth["operator"])
        assert response.status_code == 404 and "999" in response.json()["detail"]


def test_queued_campaign_is_paused_resumed_and_aborted_directly(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    cid = new_campaign(client, auth["operator"])["id"]
    act = lambda a: client.post(f"/api/v1/campaigns/{cid}/{a}", headers=auth["operator"])  # noqa: E731
    assert act("pause").json()["state"] == "paused"
    assert act("resume").json()["state"] == "queued"
    aborted = act("abort").json()
    assert aborted["state"] == "aborted" and aborted["finished_at"] is not None
    conflict = act("resume")
    assert conflict.status_code == 409 and "aborted" in conflict.json()["detail"]


def test_running_campaign_gets_a_request_for_the_runner(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    cid = new_campaign(client, auth["operator"])["id"]
    set_campaign(sf, cid, state="running")
    paused = client.post(f"/api/v1/campaigns/{cid}/pause", headers=auth["operator"]).json()
    assert paused["state"] == "running" and paused["requested_action"] == "pause"
    aborted = client.post(f"/api/v1/campaigns/{cid}/abort", headers=auth["operator"]).json()
    assert aborted["state"] == "running" and aborted["requested_action"] == "abort"


def test_completed_campaign_refuses_every_action_with_409(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    cid = new_campaign(client, auth["operator"])["id"]
    set_campaign(sf, cid, state="completed")
    for action in ("pause", "resume", "abort"):
        response = client.post(f"/api/v1/campaigns/{cid}/{action}", headers=auth["operator"])
        assert response.status_code == 409, action
    got = client.get(f"/api/v1/campaigns/{cid}", headers=auth["viewer"]).json()
    assert got["state"] == "completed" and got["progress"]["fraction"] == 1.0
