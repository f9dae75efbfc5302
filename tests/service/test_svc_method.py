"""``method``: soak runs as before; ramp is accepted at the door, dry-run with its legs and
holds, and refused with the reason where it cannot ramp (one setpoint, a soak-only key)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from svc_helpers import new_campaign

from service.cli import main


def test_method_soak_is_the_default_and_ramp_is_accepted_with_a_range(
        client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert new_campaign(client, auth["operator"])["spec"]["method"] == "soak"
    ramp = new_campaign(client, auth["operator"], method="ramp", setpoints_c=[-20, 40])
    assert ramp["spec"]["method"] == "ramp"
    # a ramp's own default rate (it measures while moving); a soak's stays 1 °C/min
    assert ramp["spec"]["ramp_c_per_min"] == 2.0
    # the stored dry run is the ramp's: 120 °C of legs at 2 °C/min and two holds, < 8 h
    assert 60 * 60 < ramp["predicted_duration_s"] < 8 * 3600
    slow = new_campaign(client, auth["operator"], method="ramp", setpoints_c=[-20, 40],
                        ramp_c_per_min=1)
    assert slow["spec"]["ramp_c_per_min"] == 1.0  # a rate given is the rate used
    # 120 °C of legs take an hour longer at half the rate; the holds are a little shorter
    assert slow["predicted_duration_s"] > ramp["predicted_duration_s"] + 30 * 60
    soak = new_campaign(client, auth["operator"], setpoints_c=[-20, 40])
    assert soak["spec"]["ramp_c_per_min"] == 1.0
    assert ramp["predicted_duration_s"] != soak["predicted_duration_s"]
    r = client.post("/api/v1/campaigns", headers=auth["operator"],
                    json={"rig": "sim", "sensor": "SN-0001", "method": "ramp",
                          "setpoints_c": [20]})
    assert r.status_code == 422, r.text
    assert "give at least two different setpoints" in json.dumps(r.json()["detail"])


def test_campaign_plan_predicts_a_ramp_with_its_legs_and_holds(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("SOAKCAL_HOME", str(tmp_path))
    assert main(["campaign", "plan", "--method", "soak", "--positions", "six", "--json"]) == 0
    soak_s = json.loads(capsys.readouterr().out)["predicted_duration_s"]
    assert main(["campaign", "plan", "--method", "ramp", "--setpoints=-40,60",
                 "--ramp-c-per-min", "3"]) == 0
    out = capsys.readouterr().out
    m = re.search(r"ramp 23 → -40 → 60 → 23 °C at 3 °C/min, holds (\d+) min at -40 °C, "
                  r"(\d+) min at 60 °C .* predicted duration (\d+) s \(([\d.]+) h", out)
    assert m, out
    # 200 °C of travel at 3 °C/min is 67 min; the holds are the 15-min die's approach to 1 °C;
    # the air's own lag (2 min) costs a few minutes more per leg
    assert 35 <= int(m[1]) <= 55 and 35 <= int(m[2]) <= 55
    holds_s = (int(m[1]) + int(m[2])) * 60
    assert 67 * 60 + holds_s <= int(m[3]) <= 67 * 60 + holds_s + 3 * 10 * 60
    assert int(m[3]) != round(soak_s)
    assert main(["campaign", "plan", "--method", "ramp", "--setpoints=20"]) == 2
    assert "give at least two different setpoints" in capsys.readouterr().err
