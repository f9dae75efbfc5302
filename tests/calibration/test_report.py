"""Reports: Table 6 layout, JSON report, PNG figures, Fig. 8 reproduction."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import thermal_sim

from calibration import report
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
