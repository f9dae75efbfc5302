"""``method``: soak runs as before; ramp is refused everywhere with the reason, never run
as a soak (the engine does not run ramp campaigns yet)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from svc_helpers import new_campaign

from service.cli import main


def test_method_soak_is_the_default_and_ramp_is_refused_naming_the_field(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert new_campaign(client, auth["operator"])["spec"]["method"] == "soak"
    assert new_campaign(client, auth["operator"], method="soak")["spec"]["method"] == "soak"
    r = client.post("/api/v1/campaigns", headers=auth["operator"],
                    json={"rig": "sim", "sensor": "SN-0001", "method": "ramp"})
    assert r.status_code == 422, r.text
    detail = json.dumps(r.json()["detail"])
    assert "method" in detail and "ramp campaigns are not run by this engine yet" in detail


def test_campaign_plan_takes_method(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("SOAKCAL_HOME", str(tmp_path))
    assert main(["campaign", "plan", "--method", "soak", "--positions", "six", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
    assert main(["campaign", "plan", "--method", "ramp", "--positions", "six"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("soakcal campaign plan: method:")
    assert "not run by this engine yet" in err[0] and '"method": "soak"' in err[0]


def test_demo_method_ramp_is_refused_before_anything_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--method", "ramp", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--method ramp" in err[0] and "soakcal calibrate" in err[0]
    assert not (tmp_path / "d").exists()
