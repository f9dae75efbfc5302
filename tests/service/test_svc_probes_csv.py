"""GET /api/v1/campaigns/{id}/probes.csv: the soak probes, one sensor's, recording-format rows."""

from __future__ import annotations

from fastapi.testclient import TestClient


def _post(client: TestClient, headers: dict[str, str], body: dict):  # type: ignore[no-untyped-def]
    return client.post("/api/v1/campaigns", json={"setpoints_c": [-10, 20], **body},
                       headers=headers)


def _probe(cid: int, serial: str, t_s: float, ax: float):  # type: ignore[no-untyped-def]
    from service.db.models import SoakProbe

    return SoakProbe(campaign_id=cid, sensor=serial, step=0, soak_start_t_s=0.0,
                     pose="0.0,0.0,0.0", t_s=t_s, setpoint_c=-10.0, chamber_c=-9.9,
                     sensor_c=-8.0, ref_x=0.0, ref_y=0.0, ref_z=1.0, ax=ax, ay=0.0, az=1.0,
                     n=250)


def test_probes_csv_is_per_sensor_and_in_time_order(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    from service.db.session import session_scope

    cid = _post(client, auth["operator"], {"rig": "sim", "sensors": ["SN-1", "SN-2"]}).json()["id"]
    with session_scope(sf) as session:
        session.add_all([_probe(cid, "SN-1", 120.0, 0.012), _probe(cid, "SN-1", 60.0, 0.011),
                         _probe(cid, "SN-2", 60.0, 0.022)])
    url = f"/api/v1/campaigns/{cid}/probes.csv"
    bare = client.get(url, headers=auth["viewer"])
    assert bare.status_code == 422 and "choose one of SN-1, SN-2" in bare.json()["detail"][0]["msg"]
    got = client.get(url, params={"sensor": "SN-1"}, headers=auth["viewer"])
    assert got.status_code == 200 and got.headers["content-type"].startswith("text/csv")
    lines = got.text.strip().splitlines()
    assert lines[0] == "t_s,step,setpoint_c,chamber_c,sensor_c,ref_x,ref_y,ref_z,ax,ay,az,n"
    assert [ln.split(",")[0] for ln in lines[1:]] == ["60.0", "120.0"]
    assert lines[1].split(",")[8] == "0.011" and lines[1].endswith(",250")
    assert f"campaign-{cid}-probes-SN-1.csv" in got.headers["content-disposition"]
    assert client.get(f"/api/v1/campaigns/{cid + 99}/probes.csv",
                      headers=auth["viewer"]).status_code == 404


def test_probes_csv_of_a_one_sensor_campaign_needs_no_sensor(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    from service.db.session import session_scope

    cid = _post(client, auth["operator"], {"rig": "sim", "sensor": "SN-9"}).json()["id"]
    with session_scope(sf) as session:
        session.add(_probe(cid, "SN-9", 60.0, 0.5))
    got = client.get(f"/api/v1/campaigns/{cid}/probes.csv", headers=auth["viewer"])
    assert got.status_code == 200 and len(got.text.strip().splitlines()) == 2
