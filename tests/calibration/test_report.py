"""Reports: Table 6 layout, JSON report, PNG figures, Fig. 8 reproduction."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration import report
from calibration.recording import Recording
from calibration.thermal import fit_campaign


@pytest.fixture(scope="module")
def fit_and_rec() -> tuple:
    _, rec = thermal_sim.campaign(seed=21)
    return fit_campaign(rec), rec


def test_table6_has_a_header_and_one_row_per_step(fit_and_rec: tuple) -> None:
    fit, _ = fit_and_rec
    text = report.format_table6(fit)
    lines = text.splitlines()
    assert "mode: reference" in lines[1] and "method: joint" in lines[1]
    assert "positions per step: 24" in lines[1]
    assert lines[2].startswith("temperature: sensor_c")
    head = next(i for i, ln in enumerate(lines) if "Before calibration" in ln)
    assert "Polynomial" in lines[head] and "Measurement" in lines[head]
    assert lines[head + 1].split() == ["(°C)", "RMSE", "(mg)", "RMSE", "(mg)", "RMSE", "(mg)"]
    rows = [ln.split() for ln in lines[head + 2 : head + 13]]
    assert [int(r[0]) for r in rows] == list(range(11))
    temps = [float(r[1]) for r in rows]
    assert temps[0] == pytest.approx(-40, abs=0.5) and temps[-1] == pytest.approx(60, abs=0.5)
    for r in rows:
        before, poly, meas = map(float, r[2:5])
        assert before > 5.0 and 0 < poly < 0.05 and 0 < meas < 0.05
    assert "µg/K" in text


def test_report_dict_is_json_and_matches_the_steps(fit_and_rec: tuple) -> None:
    fit, _ = fit_and_rec
    doc = json.loads(json.dumps(report.report_dict(fit), allow_nan=False))
    assert doc["mode"] == "reference" and len(doc["steps"]) == 11
    assert set(doc["steps"][0]) >= {"temperature_c", "rmse_before_mg", "rmse_polynomial_mg",
                                    "rmse_measurement_mg"}
    assert doc["drift"]["before"]["range_c"][0] < -39
    assert abs(doc["drift"]["after"]["slope_ug_per_k"][2]) < 1.0


def _is_png(p: Path) -> bool:
    return p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000


def test_figures_are_written(tmp_path: Path, fit_and_rec: tuple) -> None:
    fit, rec = fit_and_rec
    paths = report.write_figures(fit, rec, tmp_path / "figs")
    assert [p.name for p in paths] == ["norm_error.png", "parameters_vs_temperature.png",
                                       "drift.png"]
    assert all(_is_png(p) for p in paths)


def test_rmse_vs_positions_reproduces_the_trend_of_fig8(tmp_path: Path) -> None:
    path, rows = report.plot_rmse_vs_positions(tmp_path / "fig8.png", nops=(324, 24, 12),
                                               n_heldout=324)
    assert _is_png(path)
    held = {r["positions"]: r["rmse_heldout_ug"] for r in rows}
    assert held[12] > held[324]  # fewer positions: worse on unseen orientations
    assert all(r["rmse_before_ug"] > 100 * r["rmse_heldout_ug"] for r in rows)


def test_text_report_and_json_carry_the_coefficients_and_table5(fit_and_rec: tuple) -> None:
    fit, rec = fit_and_rec
    report.add_sections(fit, rec)
    doc = json.loads(json.dumps(report.report_dict(fit), allow_nan=False))
    coef = doc["coefficients"]
    assert len(coef["steps"]) == 11 and set(coef["steps"][0]["stderr"]) == set(
        ["bx", "by", "bz", "sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz"])
    # the physical cubic reproduces the model at a temperature
    T = 17.0
    sz = np.polyval(coef["polynomial"]["physical"]["sz"][::-1], T - coef["polynomial"]["centre_c"])
    assert sz == pytest.approx(fit.model.params_at(T).scale[2], abs=1e-12)
    assert all(s is not None and s > 0 for s in coef["polynomial"]["physical_stderr"]["bx"])
    tilt = doc["tilt_table"]
    assert tilt["rows"] and abs(tilt["temperature_c"] - 25.0) < 6.0
    for r in tilt["rows"]:
        assert r["err_cal_deg"] < 0.01 < r["err_raw_deg"]  # calibration fixes the tilt
        assert r["seoq_pitch_pct"] == pytest.approx(
            abs(r["raw_pitch_deg"] - r["cal_pitch_deg"]) / 30 * 100, abs=2e-3)
    assert tilt["rms_err_cal_deg"] < tilt["rms_err_raw_deg"] / 50
    text = report.format_table6(fit)
    assert "fitted SFEM parameters per step" in text and "polynomial coefficients" in text
    assert "tilt angles (Table 5, Eq. 10)" in text and "SEOQ" in text
    assert "-0.000" not in text


def test_no_negative_zero_in_labels() -> None:
    assert report._f(-0.0004, ".3f") == "0.000" and report._f(-0.2, ".0f") == "0"
    assert report._f(-0.0012, ".3f") == "-0.001" and report._f(-1.0, ".0f") == "-1"


def test_step_colours_stay_visible_on_white() -> None:
    def max_luma(cmap: object) -> float:
        c = cmap(np.linspace(0, 1, 101))[:, :3]  # type: ignore[operator]
        return float(np.max(0.2126 * c[:, 0] + 0.7152 * c[:, 1] + 0.0722 * c[:, 2]))

    import matplotlib.pyplot as plt

    assert max_luma(plt.get_cmap("coolwarm")) > 0.8  # the old one: near-white middle
    assert max_luma(report.step_colormap()) < 0.75


def test_no_temperature_no_parameters_figure_and_it_says_so(tmp_path: Path) -> None:
    _, rec = thermal_sim.campaign(seed=22, setpoints=(25.0,))
    cols = {k: v for k, v in rec.columns.items() if k not in ("sensor_c", "setpoint_c")}
    cols["chamber_c"] = np.full(len(rec), np.nan)  # the column is there, every cell empty
    fit = fit_campaign(Recording.from_columns(cols))
    assert not fit.model.temperature_dependent
    paths = report.write_figures(fit, rec, tmp_path / "f")
    assert [p.name for p in paths] == ["norm_error.png"]
    assert any("no parameters-vs-temperature figure" in n for n in fit.report["notes"])
    assert "no parameters-vs-temperature figure" in report.format_table6(fit)
    report.add_sections(fit, rec)  # references but no temperature: Table 5 still prints
    assert "(temperature n/a)" in report.format_table6(fit)


def test_figures_follow_the_umask(tmp_path: Path, fit_and_rec: tuple) -> None:
    # (the model file and CSVs go through recording.atomic_write_text, whose umask
    # handling is tested in test_recording_robustness.py)
    import os

    old = os.umask(0o022)
    try:
        paths = report.write_figures(fit_and_rec[0], fit_and_rec[1], tmp_path / "figs")
    finally:
        os.umask(old)
    assert all(p.stat().st_mode & 0o777 == 0o644 for p in paths)
