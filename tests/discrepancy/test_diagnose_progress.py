"""`soakcal diagnose` shows its steps on stderr while it works on a long recording.

A diagnosis of 1 M readings takes about ten minutes; a lab engineer must see that it is
working and where it is. stdout keeps the report (or the JSON) alone.
"""

from __future__ import annotations

import json
import re

import numpy as np

from calibration.discrepancy import cli as discrepancy_cli
from calibration.recording import write_recording
from service.cli import main
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

UP_DOWN = [-40.0, 10.0, 60.0, 10.0, -40.0]


def _recording(tmp_path):
    truth = SensorTruth.adxl355_typical(seed=4)
    truth.effects = [fx.ThermalHysteresis(h_g=np.array([60e-6, -40e-6, 50e-6]))]
    path = tmp_path / "r.csv"
    write_recording(path, simulate_campaign(truth, UP_DOWN, seed=54, soak_min=20))
    return path


def test_a_long_diagnosis_shows_its_steps_on_stderr(tmp_path, capsys, monkeypatch):
    path = _recording(tmp_path)
    monkeypatch.setattr(discrepancy_cli, "PROGRESS_MIN_READINGS", 100)  # 120 readings
    assert main(["diagnose", str(path), "--json", "--n-null", "40"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)  # stdout is the JSON alone
    lines = cap.err.strip().splitlines()
    assert all(re.match(r"diagnose \[\s*\d+ s\] ", line) for line in lines), lines
    steps = [line.split("] ", 1)[1] for line in lines]
    assert steps[0] == "fitting the base model to 120 readings"
    assert steps[1] == "stage 1: testing the catalogue's effects against 40 null replicates"
    assert any(s.startswith("stage 1: thermal_hysteresis stands out (p_family ") for s in steps)
    assert any(re.match(r"stage \d: no further effect \(best \w+, p_family [=<] ", s)
               for s in steps)
    assert "localised scan of the final residual" in steps
    assert steps[-1] == f"done: {len(doc['findings'])} finding(s)"
    assert doc["mismatch"] is True


def test_a_short_diagnosis_prints_nothing_on_stderr(tmp_path, capsys):
    path = _recording(tmp_path)
    assert main(["diagnose", str(path), "--n-null", "40"]) == 0
    cap = capsys.readouterr()
    assert cap.err == ""
    assert "Mismatch diagnosis of" in cap.out
