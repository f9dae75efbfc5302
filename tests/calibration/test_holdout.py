"""Leave-one-out figures, degrees of freedom and the hand-placed marker in `calibrate`."""

from __future__ import annotations

import argparse
import io
import json
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration import holdout, placement, schedules, sfem
from calibration.cli import run_calibrate
from calibration.errors import RecordingError
from calibration.recording import Recording, recording_text
from calibration.thermal import fit_campaign
from simulators.truth import SensorTruth
from tests.realdata import need_realdata


def _static_recording(directions: np.ndarray, seed: int, *, ref: bool = False,
                      tol_deg: float | None = None, tilt_deg: float = 0.0) -> Recording:
    """One step at no temperature: interval means of a typical sensor, sd and n recorded."""
    rng = np.random.default_rng(seed)
    truth = SensorTruth.adxl355_typical(seed).params_at(25.0)
    true_dirs = np.array([sfem.rotation(rng.normal(0, np.radians(tilt_deg), 3)) @ v
                          for v in directions]) if tilt_deg else directions
    n = len(directions)
    raw = truth.invert(true_dirs) + rng.normal(0.0, 10e-6, (n, 3))
    cols: dict[str, object] = {
        "t_s": np.arange(n) * 10.0, "chamber_c": np.full(n, np.nan),
        "position": np.arange(n), "ax": raw[:, 0], "ay": raw[:, 1], "az": raw[:, 2],
        "n": np.full(n, 100.0), "sd_x": np.full(n, 100e-6), "sd_y": np.full(n, 100e-6),
        "sd_z": np.full(n, 100e-6),
    }
    if ref:
        for j, c in enumerate(("ref_x", "ref_y", "ref_z")):
            cols[c] = directions[:, j]
    if tol_deg is not None:
        cols[placement.REF_TOL_COLUMN] = np.full(n, tol_deg)
    return Recording.from_columns(cols)  # type: ignore[arg-type]


def test_campaign_reports_a_held_out_error_a_little_above_the_in_sample_one() -> None:
    _, rec = thermal_sim.campaign(seed=31)
    fit = fit_campaign(rec)
    held = holdout.holdout_fields(rec, fit, warn=io.StringIO())
    assert held["warnings"] == []
    # 24 positions on three great circles of 8, which share the six axis directions:
    # 18 distinct orientations, three residuals each (reference mode)
    assert held["dof"] == {"observations": 3 * 18, "parameters": 12, "spare": 42}
    # Held-out error is larger than in-sample (the fit saw those readings) but of the
    # same size: the model is right and the positions are many.
    assert held["rmse_ug"] < held["loo_rmse_ug"] < 1.5 * held["rmse_ug"]
    assert held["loo_rmse_vector_ug"] is not None


def test_ten_positions_for_nine_parameters_warn_and_give_no_held_out_figure(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rec = _static_recording(schedules.sphere(10), seed=4)
    path = tmp_path / "ten.csv"
    path.write_text(recording_text(rec))
    ns = argparse.Namespace(recording=str(path), output=str(tmp_path / "m.json"), json=True,
                            report_dir=None, method=None)
    assert run_calibrate(ns) == 0
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert doc["loo_rmse_ug"] is None
    assert doc["dof"] == {"observations": 10, "parameters": 9, "spare": 1}
    assert len(doc["warnings"]) == 1 and "1 spare degree" in doc["warnings"][0]
    assert "warning: step 0: 1 spare degree" in out.err


def test_repeated_placements_on_too_few_faces_give_no_held_out_figure() -> None:
    # Twelve placements on the six faces of a box, each face twice: 12 positions but 6
    # distinct orientations for 6 fitted parameters (bias and scale). Leaving one
    # placement out keeps its twin, so a held-out figure would not test a direction
    # the fit did not see: no figure, and the warning names the orientations.
    faces = np.vstack([np.eye(3), -np.eye(3)])
    rec = _static_recording(np.vstack([faces, faces]), seed=6)
    held = holdout.holdout_fields(rec, fit_campaign(rec), warn=io.StringIO())
    assert held["loo_rmse_ug"] is None
    assert held["dof"]["observations"] == 6 and held["dof"]["spare"] <= 0
    assert "12 positions, 6 distinct orientations" in held["warnings"][0]


def test_enough_positions_give_a_figure_and_no_warning() -> None:
    rec = _static_recording(schedules.sphere(24), seed=5)
    held = holdout.holdout_fields(rec, fit_campaign(rec), warn=io.StringIO())
    assert held["warnings"] == [] and held["dof"]["spare"] == 15
    assert held["loo_rmse_ug"] is not None and held["loo_rmse_ug"] > held["rmse_ug"]


def test_hand_placed_column_reaches_the_fit_through_calibrate() -> None:
    labels = schedules.six_position()
    exact = _static_recording(labels, seed=6, ref=True, tilt_deg=1.0)
    hand = _static_recording(labels, seed=6, ref=True, tilt_deg=1.0, tol_deg=2.0)
    fe, fh = fit_campaign(exact), fit_campaign(hand)
    assert any("hand-placed" in n for n in fh.notes)
    assert fh.steps[0].fit.ref_tol_rad is not None and fe.steps[0].fit.ref_tol_rad is None
    # |g| on the six placements: exact where the labels are treated as approximate.
    assert fh.steps[0].rmse_measurement_ug < 20.0 < fe.steps[0].rmse_measurement_ug


def test_hand_placed_faces_warn_that_their_spare_dof_count_only_g() -> None:
    # Six hand-placed faces fit all 12 parameters (the labels a prior of ref_tol_deg), but
    # only the six |g| are observations: the warning says what it counted, so "-3 spare"
    # beside "12 of 12 identifiable" is not read as a contradiction
    hand = _static_recording(schedules.six_position(), seed=6, ref=True, tilt_deg=1.0,
                             tol_deg=2.0)
    held = holdout.holdout_fields(hand, fit_campaign(hand), warn=io.StringIO())
    assert held["loo_rmse_ug"] is None and held["dof"]["spare"] == 6 - 9
    assert ("9 parameters, reference mode; counted on |g|, one per position: the "
            "hand-placed labels are a prior of ref_tol_deg, not observations"
            in held["warnings"][0])


def test_ref_tol_column_read_from_a_file_and_bad_cells_named(tmp_path: Path) -> None:
    from calibration.recording import read_recording

    labels = schedules.six_position()
    text = recording_text(_static_recording(labels, seed=7, ref=True, tol_deg=1.5))
    p = tmp_path / "hand.csv"
    p.write_text(text)
    tol = placement.reference_tolerance_rad(read_recording(p))
    assert tol is not None and np.allclose(tol, np.radians(1.5))
    lines = text.splitlines()
    col = lines[0].split(",").index(placement.REF_TOL_COLUMN)
    for bad, msg in (("abc", "not a number"), ("", "empty"), ("-1", "-1")):
        cells = lines[3].split(",")
        cells[col] = bad
        p.write_text("\n".join(lines[:3] + [",".join(cells)] + lines[4:]) + "\n")
        with pytest.raises(RecordingError, match=msg) as err:
            placement.reference_tolerance_rad(read_recording(p))
        assert err.value.line == 4 and err.value.column == placement.REF_TOL_COLUMN


def test_calibrate_refuses_a_bad_ref_tol_cell_with_exit_2(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    labels = schedules.six_position()
    text = recording_text(_static_recording(labels, seed=8, ref=True, tol_deg=1.5))
    lines = text.splitlines()
    col = lines[0].split(",").index(placement.REF_TOL_COLUMN)
    cells = lines[2].split(",")
    cells[col] = "x"
    p = tmp_path / "bad.csv"
    p.write_text("\n".join(lines[:2] + [",".join(cells)] + lines[3:]) + "\n")
    out = tmp_path / "m.json"
    ns = argparse.Namespace(recording=str(p), output=str(out), json=True, report_dir=None,
                            method=None)
    assert run_calibrate(ns) == 2
    assert "ref_tol_deg" in capsys.readouterr().err and not out.exists()


FERRARIS = "imucal-ferraris/example_ferraris_session.csv"


def test_real_ferraris_hand_placed_beats_imucal_on_the_held_out_rests() -> None:
    """|g| on the six and on the seven other static periods vs imucal 0.04 / 0.5 mg."""
    ferraris = need_realdata(FERRARIS)
    from benchmarks.bench_realdata import other_static_periods
    from calibration import importers

    raw = importers.read_source("ferraris", ferraris)
    rec = importers.intervals_to_recording(
        raw, importers.find_intervals(raw, importers.DEFAULT_DETECTOR["ferraris"]))
    fit = fit_campaign(rec)  # the calibrate path: ref_tol_deg written by the import
    params = fit.steps[0].fit.params
    other = other_static_periods(raw)
    assert len(other) == 7
    six_mg = np.sqrt(np.mean((np.linalg.norm(params.apply(rec.raw_g), axis=1) - 1) ** 2)) * 1e3
    other_mg = np.sqrt(np.mean((np.linalg.norm(params.apply(other), axis=1) - 1) ** 2)) * 1e3
    assert six_mg < 0.04 and other_mg < 0.5, (six_mg, other_mg)
    assert fit.model.provenance["method_requested"] == "joint"


def test_too_many_folds_give_no_figure_and_say_why(monkeypatch: pytest.MonkeyPatch) -> None:
    rec = _static_recording(schedules.sphere(24), seed=9)
    monkeypatch.setattr(holdout, "MAX_LOO_FOLDS", 20)
    held = holdout.holdout_fields(rec, fit_campaign(rec), warn=io.StringIO())
    assert held["loo_rmse_ug"] is None
    assert "24 refits" in held["warnings"][0]
