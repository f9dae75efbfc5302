"""Rigs can be replaced, patched, deleted (not while used) and checked over REST and the CLI."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from svc_helpers import new_campaign, set_campaign

LAB = {
    "name": "lab-1",
    "chamber": {"driver": "modbus", "url": "tcp://10.0.0.5:502", "map": "eurotherm-3216"},
    "turntable": {"url": "tcp://10.0.0.6:502"},
    "sensors": [{"url": "/dev/ttyUSB0"}],
}


def test_put_patch_delete(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.post("/api/v1/rigs", json=LAB, headers=auth["admin"]).status_code == 201
    new = {k: v for k, v in LAB.items() if k != "name"}
    new["chamber"] = {**LAB["chamber"], "map": "watlow-f4t"}
    r = client.put("/api/v1/rigs/lab-1", json=new, headers=auth["admin"])
    assert r.status_code == 200 and r.json()["chamber"]["map"] == "watlow-f4t"
    r = client.patch("/api/v1/rigs/lab-1", json={"sensors": [{"url": "/dev/ttyACM0"}]},
                     headers=auth["admin"])
    assert r.status_code == 200
    assert r.json()["sensors"] == [{"url": "/dev/ttyACM0"}]
    assert r.json()["chamber"]["map"] == "watlow-f4t"  # untouched section kept
    r = client.patch("/api/v1/rigs/lab-1", json={"chamber": {**LAB["chamber"], "map": "nope"}},
                     headers=auth["admin"])
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "chamber", "map"]
    assert client.patch("/api/v1/rigs/lab-1", json={}, headers=auth["operator"]).status_code \
        == 403
    assert client.put("/api/v1/rigs/nope", json=new, headers=auth["admin"]).status_code == 404
    assert client.delete("/api/v1/rigs/lab-1", headers=auth["admin"]).status_code == 204
    names = [x["name"] for x in client.get("/api/v1/rigs", headers=auth["viewer"]).json()]
    assert names == ["sim"]
    assert client.delete("/api/v1/rigs/lab-1", headers=auth["admin"]).status_code == 404


@pytest.mark.parametrize("state", ["queued", "running", "paused", "completed"])
def test_a_rig_a_campaign_uses_or_names_is_not_deleted_nor_changed(  # type: ignore[no-untyped-def]
        client: TestClient, auth, sf, state: str) -> None:
    campaign = new_campaign(client, auth["operator"])
    set_campaign(sf, campaign["id"], state=state)
    r = client.delete("/api/v1/rigs/sim", headers=auth["admin"])
    assert r.status_code == 409 and "sim" in r.json()["detail"]
    r = client.patch("/api/v1/rigs/sim", json={"sensors": []}, headers=auth["admin"])
    assert r.status_code == (200 if state == "completed" else 409)


def test_check_endpoint_on_the_sim_rig(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    r = client.post("/api/v1/rigs/sim/check", json={"move": True}, headers=auth["operator"])
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["rig"] == "sim" and body["passed"] is True
    assert {c["check"] for c in body["checks"]} >= {"identity", "status", "setpoint_nudge",
                                                     "table_move", "acquire"}
    assert client.post("/api/v1/rigs/sim/check", headers=auth["viewer"]).status_code == 403
    assert client.post("/api/v1/rigs/nope/check", headers=auth["admin"]).status_code == 404
    campaign = new_campaign(client, auth["operator"])
    set_campaign(sf, campaign["id"], state="running")
    assert client.post("/api/v1/rigs/sim/check", headers=auth["admin"]).status_code == 409


def test_cli_rig_check(client: TestClient, settings, monkeypatch,  # type: ignore[no-untyped-def]
                       capsys: pytest.CaptureFixture[str]) -> None:
    from service.cli import main

    monkeypatch.setenv("SOAKCAL_DATABASE_URL", settings.database_url)
    assert main(["rig", "check", "sim"]) == 0
    out = capsys.readouterr().out
    assert "PASS  chamber" in out and "0 failed" in out
    assert main(["rig", "check", "nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nope" in err and "sim" in err
    bad = {**LAB, "name": "dead",
           "chamber": {**LAB["chamber"], "url": "tcp://127.0.0.1:9"},
           "turntable": {"url": "tcp://127.0.0.1:9", "device_id": 2},
           "sensors": [{"url": "socket://127.0.0.1:9"}]}
    assert client.post("/api/v1/rigs", json=bad, headers={**_admin(client)}).status_code == 201
    assert main(["rig", "check", "dead", "--json"]) == 1
    assert '"passed": false' in capsys.readouterr().out


def _admin(client: TestClient) -> dict[str, str]:
    from service.api.auth import create_token
    from service.db.session import session_scope

    with session_scope(client.app.state.session_factory) as s:  # type: ignore[attr-defined]
        return {"Authorization": f"Bearer {create_token(s, 'admin')}"}


# --- rig add | list | rm, and the rules they share with the API -----------------------


def _cli(monkeypatch, url: str, *argv: str) -> int:  # type: ignore[no-untyped-def]
    from service.cli import main

    monkeypatch.setenv("SOAKCAL_DATABASE_URL", url)
    return main(list(argv))


def test_cli_rig_add_list_rm(tmp_path, monkeypatch,  # type: ignore[no-untyped-def]
                             capsys: pytest.CaptureFixture[str]) -> None:
    import json

    url = f"sqlite:///{tmp_path / 'fresh.db'}"  # a fresh install: no `serve` has run
    cfg = tmp_path / "lab.json"
    cfg.write_text(json.dumps({k: v for k, v in LAB.items() if k != "name"}))
    assert _cli(monkeypatch, url, "rig", "add", "lab-1", "--config", str(cfg)) == 0
    assert "rig lab-1 added: chamber modbus tcp://10.0.0.5:502" in capsys.readouterr().out
    assert _cli(monkeypatch, url, "rig", "list") == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[1].split()[:2] == ["lab-1", "no"] and rows[2].split() == ["sim", "no", "sim"]
    assert _cli(monkeypatch, url, "rig", "add", "lab-1", "--config", str(cfg)) == 2
    assert "already exists" in capsys.readouterr().err
    assert _cli(monkeypatch, url, "rig", "rm", "lab-1") == 0
    assert capsys.readouterr().out.strip() == "rig lab-1 removed"
    assert _cli(monkeypatch, url, "rig", "rm", "lab-1") == 2
    assert "no rig 'lab-1'" in capsys.readouterr().err


def test_cli_rig_add_names_file_and_key_of_a_misspelt_limit(  # type: ignore[no-untyped-def]
        tmp_path, monkeypatch, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    url = f"sqlite:///{tmp_path / 'fresh.db'}"
    cfg = tmp_path / "lab.json"
    cfg.write_text(json.dumps({"chamber": {**LAB["chamber"], "rnage_c": [-40, 85]},
                               "turntable": LAB["turntable"], "sensors": LAB["sensors"]}))
    assert _cli(monkeypatch, url, "rig", "add", "lab-1", "--config", str(cfg)) == 2
    # (the first line says which database, as every database subcommand does)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith(f"soakcal rig add: {cfg}: chamber.rnage_c: unknown key")
    assert "did you mean 'range_c'?" in err
    assert _cli(monkeypatch, url, "rig", "list") == 0
    assert "lab-1" not in capsys.readouterr().out  # nothing stored


def test_cli_rig_check_sim_on_a_fresh_database(tmp_path, monkeypatch,  # type: ignore[no-untyped-def]
                                               capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'fresh.db'}"
    assert _cli(monkeypatch, url, "rig", "check", "sim") == 0
    assert "PASS  chamber" in capsys.readouterr().out


def test_cli_rig_check_refuses_a_rig_a_campaign_holds(  # type: ignore[no-untyped-def]
        client: TestClient, settings, auth, sf, monkeypatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    campaign = new_campaign(client, auth["operator"])
    set_campaign(sf, campaign["id"], state="running")
    assert _cli(monkeypatch, settings.database_url, "rig", "check", "sim", "--move") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "runs a campaign now" in err
