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


def test_admin_registers_a_modbus_rig_and_bad_configs_get_422(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    lab = {
        "name": "lab-1",
        "chamber": {"driver": "modbus", "url": "tcp://10.0.0.5:502", "map": "watlow_f4t",
                    "range_c": [-40, 85]},
        "turntable": {"url": "tcp://10.0.0.6:502", "axes": 2},
        "sensors": [{"url": "/dev/ttyUSB0"}],
    }
    r = client.post("/api/v1/rigs", json=lab, headers=auth["admin"])
    assert r.status_code == 201, r.text
    assert r.json()["chamber"]["map"] == "watlow_f4t" and r.json()["busy"] is False

    bad = {**lab, "name": "lab-2", "turntable": {"url": "modbus://nowhere"}, "sensors": []}
    r = client.post("/api/v1/rigs", json=bad, headers=auth["admin"])
    assert r.status_code == 422
    locs = [d["loc"] for d in r.json()["detail"]]
    assert ["body", "turntable", "url"] in locs and ["body", "sensors", 0, "url"] in locs
    names = [x["name"] for x in client.get("/api/v1/rigs", headers=auth["viewer"]).json()]
    assert names == ["lab-1", "sim"]
    r = client.post("/api/v1/rigs", json=lab, headers=auth["operator"])
    assert r.status_code == 403


def test_rigs_file_registers_rigs_at_start_and_a_bad_one_stops_the_start(  # type: ignore[no-untyped-def]
    settings, tmp_path
) -> None:
    import dataclasses
    import json

    import pytest

    from service.api.app import create_app
    from service.api.auth import create_token
    from service.db.session import session_scope

    rig = {"name": "lab-sim", "chamber": {"driver": "modbus", "url": "tcp://sim-rig:5020",
                                           "time_scale": 600},
           "turntable": {"url": "tcp://sim-rig:5021"}, "sensors": [{"url": "socket://sim-rig:5022"}]}
    path = tmp_path / "rigs.json"
    path.write_text(json.dumps([rig]))
    with TestClient(create_app(dataclasses.replace(settings, rigs_file=str(path)))) as c:
        with session_scope(c.app.state.session_factory) as s:  # type: ignore[attr-defined]
            token = create_token(s, "viewer")
        rigs = c.get("/api/v1/rigs", headers={"Authorization": f"Bearer {token}"}).json()
    assert [r["name"] for r in rigs] == ["lab-sim", "sim"]
    assert rigs[0]["chamber"]["time_scale"] == 600

    path.write_text(json.dumps([{**rig, "turntable": {"url": "udp://x"}}]))
    bad_app = create_app(dataclasses.replace(settings, rigs_file=str(path)))
    with pytest.raises(ValueError, match=r"rig 'lab-sim': turntable.url"), TestClient(bad_app):
        pass


LAB = {
    "name": "lab-9",
    "chamber": {"driver": "modbus", "url": "tcp://10.0.0.5:502", "map": "eurotherm-3216"},
    "turntable": {"url": "tcp://10.0.0.6:502"},
    "sensors": [{"url": "/dev/ttyUSB0"}],
}


def _refusal(client: TestClient, auth, rig: dict) -> list[tuple[list, str]]:  # type: ignore[no-untyped-def, type-arg]
    r = client.post("/api/v1/rigs", json=rig, headers=auth["admin"])
    assert r.status_code == 422, r.text
    return [(d["loc"], d["msg"]) for d in r.json()["detail"]]


def test_a_misspelt_chamber_key_is_refused_not_ignored(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    rig = {**LAB, "chamber": {**LAB["chamber"], "rnage_c": [-40, 85]}}
    (loc, msg), = _refusal(client, auth, rig)
    assert loc == ["body", "chamber", "rnage_c"] and "did you mean 'range_c'?" in msg


def test_a_chamber_without_driver_is_refused(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    rig = {**LAB, "chamber": {"url": "tcp://10.0.0.5:502", "garbage": 1}}
    found = dict((tuple(loc), msg) for loc, msg in _refusal(client, auth, rig))
    assert "missing" in found[("body", "chamber", "driver")]
    assert "unknown key" in found[("body", "chamber", "garbage")]


def test_limits_beyond_the_map_are_refused(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    rig = {**LAB, "chamber": {**LAB["chamber"], "range_c": [-70, 200]}}
    (loc, msg), = _refusal(client, auth, rig)
    assert loc == ["body", "chamber", "range_c"]
    assert "exceeds the map eurotherm-3216's limits.range_c [-70, 180]" in msg


def test_a_map_file_that_is_not_utf8_is_a_422_naming_the_file(  # type: ignore[no-untyped-def]
        client: TestClient, auth, tmp_path) -> None:
    bad = tmp_path / "latin1.toml"
    bad.write_bytes('name = "régulateur"\n'.encode("latin-1"))
    rig = {**LAB, "chamber": {**LAB["chamber"], "map": str(bad)}}
    (loc, msg), = _refusal(client, auth, rig)
    assert loc == ["body", "chamber", "map"]
    assert msg.startswith(f"{bad}: not UTF-8 text") and "save the map file as UTF-8" in msg


def test_a_map_with_a_4xxxx_address_is_a_422_naming_file_and_key(  # type: ignore[no-untyped-def]
        client: TestClient, auth, tmp_path) -> None:
    from drivers.registermaps import shipped_maps

    text = shipped_maps()["eurotherm-3216"].read_text()
    path = tmp_path / "lab.toml"
    path.write_text(text.replace("[registers.process_c]\naddress = 32770  # 0x8000 + 2 * 1\n",
                                 "[registers.process_c]\naddress = 40002\n"))
    rig = {**LAB, "chamber": {**LAB["chamber"], "map": str(path)}}
    (loc, msg), = _refusal(client, auth, rig)
    assert msg.startswith(f"{path}: registers.process_c.address: 40002 looks like a 4xxxx")
    assert "address = 1;" in msg


def test_a_chamber_and_table_on_one_bus_need_different_unit_ids(  # type: ignore[no-untyped-def]
        client: TestClient, auth) -> None:
    bus = "rtu:///dev/ttyUSB0?baudrate=19200"
    rig = {**LAB, "chamber": {**LAB["chamber"], "url": bus}, "turntable": {"url": bus}}
    (loc, msg), = _refusal(client, auth, rig)
    assert loc == ["body", "turntable", "device_id"]
    assert "the chamber answers unit 1 at the same url" in msg
    rig["turntable"] = {"url": bus, "device_id": 2}
    assert client.post("/api/v1/rigs", json=rig, headers=auth["admin"]).status_code == 201
