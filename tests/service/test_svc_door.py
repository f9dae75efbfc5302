"""The door: dry run at POST, bounded ids, body limit, auth before the body, short 422s."""

from __future__ import annotations

import datetime as dt
import threading

import pytest
from fastapi.testclient import TestClient

from calibration.position_order import step_orders, travel_s
from drivers.geometry import angles_for_references
from service.api.app import create_app
from service.config import Settings
from service.engine.spec import schedule_refs

CAMPAIGNS = "/api/v1/campaigns"
SCHEDULES = "/api/v1/schedules"


def _locs(response) -> list:  # type: ignore[no-untyped-def]
    assert response.status_code == 422, response.text
    return [e["loc"] for e in response.json()["detail"]]


def test_a_schedule_that_cannot_identify_the_model_is_refused(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    body = {"rig": "sim", "sensor": "SN-1", "positions": "sphere1"}
    response = client.post(CAMPAIGNS, json=body, headers=auth["operator"])
    assert _locs(response) == [["body", "positions"]]
    assert "reference mode" in response.json()["detail"][0]["msg"]
    sched = client.post(SCHEDULES, json={"campaign": body, "cron": "0 20 * * *"},
                        headers=auth["operator"])
    assert _locs(sched) == [["body", "campaign", "positions"]]
    huge = client.post(CAMPAIGNS, json={**body, "positions": "sphere999999999"},
                       headers=auth["operator"])
    assert _locs(huge) == [["body", "positions"]]


def test_setpoints_ramp_and_safe_temperature_are_checked_against_the_chamber(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    body = {"rig": "sim", "sensor": "SN-1", "setpoints_c": [20, 190], "ramp_c_per_min": 10.0,
            "safe_c": -80}
    locs = _locs(client.post(CAMPAIGNS, json=body, headers=auth["operator"]))
    assert sorted(map(str, locs)) == sorted(map(str, [
        ["body", "setpoints_c", 1], ["body", "safe_c"], ["body", "ramp_c_per_min"]]))


def test_201_carries_the_predicted_duration(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    body = {"rig": "sim", "sensor": "SN-1", "setpoints_c": [-10, 20], "soak_min": 30,
            "stability": "fixed", "ramp_c_per_min": 2.0, "positions": "six",
            "samples_per_position": 125, "settle_s": 3.0, "odr_hz": 62.5}
    response = client.post(CAMPAIGNS, json=body, headers=auth["operator"])
    assert response.status_code == 201, response.text
    # ramps 23 → −10 → 20 °C at 2 °C/min, two fixed 30 min soaks, 12 positions of
    # 3 s settle + 2 s acquisition, and the table's moves in the travel order (from home,
    # step 1 from where step 0 ended), each + 1 s to see it in position
    poses = angles_for_references(schedule_refs("six"))
    orders = step_orders(poses, 2, "travel")
    moves_s = (travel_s(poses, orders[0], (0.0, 0.0, 0.0))
               + travel_s(poses, orders[1], tuple(poses[orders[0][-1]])) + 12 * 1.0)
    expected_s = 63 / 2 * 60 + 2 * 30 * 60 + 12 * (3.0 + 2.0) + moves_s
    assert response.json()["predicted_duration_s"] == pytest.approx(expected_s)
    assert client.get(f"{CAMPAIGNS}/{response.json()['id']}", headers=auth["viewer"]).json()[
        "predicted_duration_s"] == pytest.approx(expected_s)
    # Eight sensors are read at once: the same duration; the schedule's order moves more.
    eight = client.post(CAMPAIGNS, json={**{k: v for k, v in body.items() if k != "sensor"},
                                         "sensors": [f"SN-{i}" for i in range(8)]},
                        headers=auth["operator"])
    assert eight.json()["predicted_duration_s"] == pytest.approx(expected_s)
    table = client.post(CAMPAIGNS, json={**body, "position_order": "table"},
                        headers=auth["operator"])
    assert table.json()["predicted_duration_s"] > expected_s + 5.0


def test_a_random_order_without_a_seed_is_422_naming_the_seed(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    body = {"rig": "sim", "sensor": "SN-1", "position_order": "random"}
    assert _locs(client.post(CAMPAIGNS, json=body, headers=auth["operator"])) == [
        ["body", "position_order_seed"]]
    ok = client.post(CAMPAIGNS, json={**body, "position_order_seed": 7},
                     headers=auth["operator"])
    assert ok.status_code == 201, ok.text
    assert ok.json()["spec"]["position_order"] == "random"
    assert ok.json()["spec"]["position_order_seed"] == 7


def test_schedules_at_in_the_past_and_exactly_one_trigger(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    campaign = {"rig": "sim", "sensor": "SN-1"}
    past = (dt.datetime.now(dt.UTC) - dt.timedelta(minutes=1)).isoformat()
    assert _locs(client.post(SCHEDULES, json={"campaign": campaign, "at": past},
                             headers=auth["operator"])) == [["body", "at"]]
    for body in ({"campaign": campaign}, {"campaign": campaign, "at": None, "cron": "0 1 * * *"}):
        assert client.post(SCHEDULES, json=body, headers=auth["operator"]).status_code == 422
    schema = client.get("/openapi.json").json()["components"]["schemas"]["ScheduleCreate"]
    assert [branch["required"] for branch in schema["oneOf"]] == [["at"], ["cron"]]
    future = (dt.datetime.now(dt.UTC) + dt.timedelta(days=1)).isoformat()
    created = client.post(SCHEDULES, json={"campaign": campaign, "at": future},
                          headers=auth["operator"])
    assert created.status_code == 201 and created.json()["predicted_duration_s"] > 0


@pytest.mark.parametrize("bad_id", ["0", "-1", str(2**31), str(2**63), str(2**70)])
def test_out_of_range_ids_are_422(client: TestClient, auth, bad_id: str) -> None:  # type: ignore[no-untyped-def]
    viewer, operator = auth["viewer"], auth["operator"]
    for method, path, headers in [
        ("GET", f"{CAMPAIGNS}/{bad_id}", viewer),
        ("POST", f"{CAMPAIGNS}/{bad_id}/pause", operator),
        ("POST", f"{CAMPAIGNS}/{bad_id}/abort", operator),
        ("GET", f"{CAMPAIGNS}/{bad_id}/recording.csv", viewer),
        ("GET", f"{CAMPAIGNS}/{bad_id}/events", viewer),
        ("GET", f"/api/v1/calibrations/{bad_id}", viewer),
        ("DELETE", f"{SCHEDULES}/{bad_id}", operator),
    ]:
        assert client.request(method, path, headers=headers).status_code == 422, path
    assert client.get(f"{CAMPAIGNS}/{2**31 - 1}", headers=viewer).status_code == 404


def test_serials_are_a_pattern(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    response = client.post(CAMPAIGNS, json={"rig": "sim", "sensor": "SN/1"},
                           headers=auth["operator"])
    assert _locs(response) == [["body", "sensor"]]
    ok = client.post(CAMPAIGNS, json={"rig": "sim", "sensor": "SN-1.a:b_2"},
                     headers=auth["operator"])
    assert ok.status_code == 201
    calibrations = client.get("/api/v1/sensors/SN-1.a:b_2/calibrations", headers=auth["viewer"])
    assert calibrations.status_code == 200 and calibrations.json() == []


def test_concurrent_first_posts_for_a_new_serial_all_succeed(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    for serial in ("SN-RACE-1", "SN-RACE-2", "SN-RACE-3"):  # three races, three chances
        statuses: list[int] = []
        barrier = threading.Barrier(6)

        def post(serial: str = serial, barrier: threading.Barrier = barrier,
                 statuses: list[int] = statuses) -> None:
            barrier.wait()
            response = client.post(CAMPAIGNS, json={"rig": "sim", "sensor": serial},
                                   headers=auth["operator"])
            statuses.append(response.status_code)

        threads = [threading.Thread(target=post) for _ in range(6)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert statuses == [201] * 6, serial
        listed = client.get(CAMPAIGNS, headers=auth["viewer"]).json()
        assert sum(c["sensor"] == serial for c in listed) == 6


def test_body_limit_before_parsing_and_auth_before_the_body(settings: Settings, auth) -> None:  # type: ignore[no-untyped-def]
    settings.max_body_bytes = 10_000
    with TestClient(create_app(settings)) as client:
        big = b'{"rig": "' + b"x" * 20_000 + b'"}'
        json_type = {"Content-Type": "application/json"}
        assert client.post(CAMPAIGNS, content=big, headers=json_type).status_code == 401
        assert client.post(CAMPAIGNS, content=b"{not json", headers=json_type).status_code == 401
        assert client.post(CAMPAIGNS, json={"rig": 1}).status_code == 401
        # the token of the shared database fixture is valid in this app too
        operator = {**auth["operator"], **json_type}
        assert client.post(CAMPAIGNS, content=big, headers=operator).status_code == 413

        def chunks():  # no Content-Length: counted while streaming
            for _ in range(20):
                yield b" " * 1000

        assert client.post(CAMPAIGNS, content=chunks(), headers=operator).status_code == 413
        not_utf8 = client.post(CAMPAIGNS, content=b'{"rig": "\xff"}', headers=operator)
        assert not_utf8.status_code == 422 and not_utf8.json()["detail"][0]["type"] == (
            "json_invalid")
        assert client.post(CAMPAIGNS, content=b"{not json", headers=operator).status_code == 422


def test_422_echoes_only_a_short_prefix(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    long = "y" * 500_000
    for body in ({"rig": "sim", "sensor": long}, {"rig": "sim", "sensor": "S", long: 1},
                 {"rig": "sim", "sensor": "S", "setpoints_c": [long]}):
        response = client.post(CAMPAIGNS, json=body, headers=auth["operator"])
        assert response.status_code == 422 and len(response.content) < 2_000


def test_every_protected_operation_documents_401_and_403(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    secured = [(p, m, op) for p, item in paths.items() for m, op in item.items()
               if op.get("security")]
    assert len(secured) >= 10
    for path, method, op in secured:
        assert {"401", "403"} <= set(op["responses"]), (method, path)
    assert "security" not in paths["/api/v1/health"]["get"]


def test_a_wrong_method_lists_every_method_of_the_path(client: TestClient) -> None:
    response = client.request("OPTIONS", "/api/v1/rigs")
    assert response.status_code == 405 and response.headers["allow"] == "GET, POST"
    assert client.put(f"{CAMPAIGNS}/3/pause").headers["allow"] == "POST"
