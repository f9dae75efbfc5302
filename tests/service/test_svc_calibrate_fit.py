"""The service's fitting phase and ``soakcal calibrate`` give the same answer on the same data."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from calibration.cli import run_calibrate
from calibration.plateaus import segment_recording
from calibration.recording import Recording, write_recording
from service.engine.calibrate import CalibrationRow, calibrate_columns
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

COLUMNS = ("t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position", "ref_x", "ref_y",
           "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z")  # store.measurement_columns


def test_a_campaign_is_fitted_as_steps_by_the_service_and_by_calibrate_alike(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    # 20 min soaks (die τ 600 s): each step's die still creeps during the sweep, so by the
    # excursion rule alone its declared steps are no plateaus; at their held setpoints they
    # are soaks whose die follows the step's line (calibration/plateaus.py): steps, both ways.
    rec = simulate_campaign(SensorTruth.adxl355_typical(12), (-20.0, 20.0, 60.0),
                            soak_min=20.0, seed=13, physics=RigPhysics(die_tau_s=600.0))
    numbered = Recording.from_columns({k: v for k, v in rec.columns.items()
                                       if k != "setpoint_c"})
    assert segment_recording(numbered).continuous_rows == len(rec)  # the case that matters

    columns = {k: [float(v) for v in rec.columns[k]] for k in COLUMNS}
    row = calibrate_columns(columns, {"recording": "campaign-1.csv", "campaign_id": 1})
    assert isinstance(row, CalibrationRow)
    assert (row.fit.kind, row.fit.method) == ("sfem", "joint")
    assert row.report["method"] == "joint" and row.model_version == "sfem-cubic-1"
    assert row.rmse_ug == pytest.approx(row.fit.rmse_ug) and 3.0 < row.rmse_ug < 30.0
    assert (row.valid_lo_c, row.valid_hi_c) == pytest.approx(row.fit.valid_c)
    assert set(row.columns()) == {"valid_lo_c", "valid_hi_c", "rmse_ug", "model_version",
                                  "model", "report", "provenance"}

    src, out = tmp_path / "recording.csv", tmp_path / "model.json"
    write_recording(src, rec)
    ns = argparse.Namespace(recording=str(src), output=str(out), json=True, report_dir=None,
                            method=None)
    assert run_calibrate(ns) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["method"] == "joint" and doc["notes"][0] == row.fit.reason
    cli_model = json.loads(out.read_text())
    assert cli_model["polynomial"] == row.model["polynomial"]
    assert cli_model["temperature"] == row.model["temperature"]
    assert cli_model["notes"] == row.model["notes"]
