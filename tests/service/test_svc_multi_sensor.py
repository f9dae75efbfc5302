"""Several sensors per campaign at the door: `sensors`, each once, mounted on a real rig."""

from __future__ import annotations

from fastapi.testclient import TestClient
from svc_helpers import new_campaign

LAB = {
    "name": "lab-8",
    "chamber": {"driver": "modbus", "url": "tcp://10.0.0.5:502", "map": "eurotherm-3216"},
    "turntable": {"url": "tcp://10.0.0.6:502"},
    "sensors": [{"url": "/dev/ttyUSB0", "serial": "SN-1"},
                {"url": "/dev/ttyUSB1", "serial_binding": "table",
                 "serials": {"E6614104035F2B2F": "SN-2"}}],
}


def _post(client: TestClient, headers: dict[str, str], body: dict):  # type: ignore[no-untyped-def]
    return client.post("/api/v1/campaigns", json=body, headers=headers)


def test_sensors_list_is_stored_and_the_first_is_the_campaign_sensor(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    body = {"rig": "sim", "sensors": ["SN-A", "SN-B", "SN-C"]}
    created = _post(client, auth["operator"], body)
    assert created.status_code == 201, created.text
    c = created.json()
    assert c["sensor"] == "SN-A" and c["sensors"] == ["SN-A", "SN-B", "SN-C"]
    assert c["spec"]["sensors"] == ["SN-A", "SN-B", "SN-C"] and "sensor" not in c["spec"]
    assert c["calibration_ids"] == {}
    # one-sensor campaigns read as before, with the list of one
    one = new_campaign(client, auth["operator"], sensor="SN-9")
    assert one["sensor"] == "SN-9" and one["sensors"] == ["SN-9"]
    assert "sensors" not in one["spec"]


def test_a_sensor_named_twice_is_422_naming_it(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    r = _post(client, auth["operator"], {"rig": "sim", "sensors": ["SN-1", "SN-2", "SN-1"]})
    assert r.status_code == 422
    (err,) = r.json()["detail"]
    assert err["loc"] == ["body", "sensors"] and "'SN-1' is named twice" in err["msg"]


def test_exactly_one_of_sensor_and_sensors(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    both = _post(client, auth["operator"], {"rig": "sim", "sensor": "SN-1", "sensors": ["SN-2"]})
    assert both.status_code == 422
    assert both.json()["detail"][0]["loc"] == ["body", "sensor"]
    assert "not both" in both.json()["detail"][0]["msg"]
    neither = _post(client, auth["operator"], {"rig": "sim"})
    assert neither.status_code == 422
    assert [d["loc"] for d in neither.json()["detail"]] == [["body", "sensor"]]
    empty = _post(client, auth["operator"], {"rig": "sim", "sensors": []})
    assert empty.status_code == 422 and empty.json()["detail"][0]["loc"] == ["body", "sensors"]


def test_a_sensor_not_mounted_on_a_real_rig_is_422_naming_it(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.post("/api/v1/rigs", json=LAB, headers=auth["admin"]).status_code == 201
    ok = _post(client, auth["operator"], {"rig": "lab-8", "sensors": ["SN-2", "SN-1"]})
    assert ok.status_code == 201, ok.text
    bad = _post(client, auth["operator"], {"rig": "lab-8", "sensors": ["SN-1", "SN-7"]})
    assert bad.status_code == 422
    (err,) = bad.json()["detail"]
    assert err["loc"] == ["body", "sensors", 1]
    assert "'SN-7' is not mounted on rig 'lab-8'" in err["msg"] and "SN-1, SN-2" in err["msg"]
    # the sim twin mounts whatever a campaign names
    assert _post(client, auth["operator"], {"rig": "sim", "sensors": ["SN-7"]}).status_code == 201


def test_recording_csv_is_per_sensor(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    from service.db.models import Measurement
    from service.db.session import session_scope

    created = _post(client, auth["operator"], {"rig": "sim", "sensors": ["SN-1", "SN-2"]})
    cid = created.json()["id"]
    with session_scope(sf) as session:
        for serial, ax in (("SN-1", 0.011), ("SN-2", 0.022)):
            session.add(Measurement(
                campaign_id=cid, sensor=serial, step=0, position=0, t_s=10.0, setpoint_c=20.0,
                chamber_c=20.0, sensor_c=21.0, ref_x=0.0, ref_y=0.0, ref_z=1.0, ax=ax, ay=0.0,
                az=1.0, n=200))
    url = f"/api/v1/campaigns/{cid}/recording.csv"
    bare = client.get(url, headers=auth["viewer"])
    assert bare.status_code == 422
    (err,) = bare.json()["detail"]
    assert err["loc"] == ["query", "sensor"] and "choose one of SN-1, SN-2" in err["msg"]
    wrong = client.get(url, params={"sensor": "SN-3"}, headers=auth["viewer"])
    assert wrong.status_code == 422 and "no sensor 'SN-3'" in wrong.json()["detail"][0]["msg"]
    two = client.get(url, params={"sensor": "SN-2"}, headers=auth["viewer"])
    assert two.status_code == 200
    lines = two.text.strip().splitlines()
    assert len(lines) == 2 and ",0.022," in lines[1]
    assert f"campaign-{cid}-SN-2.csv" in two.headers["content-disposition"]
    got = client.get(f"/api/v1/campaigns/{cid}", headers=auth["viewer"]).json()
    assert got["sensors_dropped"] == {} and got["sensors"] == ["SN-1", "SN-2"]


MUX_LAB = {**LAB, "name": "lab-mux",
           "sensors": [{"url": "/dev/ttyACM0", "serial_binding": "eeprom",
                        "channels": {"0": "SN-1", "1": "SN-2", "2": "SN-3"}}]}


def test_a_multiplexing_bridge_mounts_its_channels_serials(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.post("/api/v1/rigs", json=MUX_LAB, headers=auth["admin"]).status_code == 201
    ok = _post(client, auth["operator"], {"rig": "lab-mux", "sensors": ["SN-3", "SN-1"]})
    assert ok.status_code == 201, ok.text
    bad = _post(client, auth["operator"], {"rig": "lab-mux", "sensors": ["SN-1", "SN-4"]})
    assert bad.status_code == 422
    (err,) = bad.json()["detail"]
    assert err["loc"] == ["body", "sensors", 1]
    assert "'SN-4' is not mounted on rig 'lab-mux'" in err["msg"]
    assert "SN-1, SN-2, SN-3" in err["msg"]


def test_a_bad_channels_entry_is_422_naming_the_key(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    bad = {**MUX_LAB, "name": "lab-bad", "sensors": [
        {"url": "/dev/ttyACM0", "channels": {"0": "SN-1", "one": "SN-2", "2": "SN-1"}},
        {"url": "/dev/ttyACM0", "serial": "SN-9"}]}
    r = client.post("/api/v1/rigs", json=bad, headers=auth["admin"])
    assert r.status_code == 422
    errors = {tuple(d["loc"]): d["msg"] for d in r.json()["detail"]}
    assert set(errors) == {("body", "sensors", 0, "channels", "one"),
                           ("body", "sensors", 0, "channels", 2),
                           ("body", "sensors", 1, "url")}
    assert "channel number 0..99" in errors[("body", "sensors", 0, "channels", "one")]
    assert "already on channel 0" in errors[("body", "sensors", 0, "channels", 2)]
    assert "'channels'" in errors[("body", "sensors", 1, "url")]
