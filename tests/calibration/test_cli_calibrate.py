"""`soakcal calibrate` / `soakcal compensate` (docs/cli.md): exit codes, files, columns."""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration.cli import run_calibrate, run_compensate
from calibration.recording import recording_text

ROOT = Path(__file__).resolve().parents[2]


def _calibrate(recording: Path, output: Path, **kw: object) -> int:
    ns = argparse.Namespace(recording=str(recording), output=str(output), json=False,
                            report_dir=None, method=None)
    for k, v in kw.items():
        setattr(ns, k, v)
    return run_calibrate(ns)


def _compensate(model: Path, recording: Path, output: Path, extrapolate: bool = False,
                **kw: object) -> int:
    return run_compensate(argparse.Namespace(model=str(model), recording=str(recording),
                                             output=str(output), extrapolate=extrapolate, **kw))


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cli")
    _, rec = thermal_sim.campaign(seed=31)
    camp = d / "campaign.csv"
    camp.write_text(recording_text(rec))
    model = d / "model.json"
    assert _calibrate(camp, model) == 0
    return {"dir": d, "campaign": camp, "model": model}


def test_calibrate_writes_a_model_and_prints_table6(files: dict, capsys: pytest.CaptureFixture,
                                                    tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    rc = _calibrate(files["campaign"], out, method="per_step", report_dir=str(tmp_path / "r"))
    assert rc == 0
    text = capsys.readouterr().out
    assert "Before calibration" in text and "method: per_step" in text
    assert "fitted SFEM parameters per step" in text and "tilt angles (Table 5" in text
    assert "local gravity cannot be identified in a static tumble" in text
    assert json.loads(out.read_text())["method"] == "per_step"
    assert (tmp_path / "r" / "parameters_vs_temperature.png").exists()


def test_calibrate_json_prints_only_json(files: dict, capsys: pytest.CaptureFixture,
                                         tmp_path: Path) -> None:
    assert _calibrate(files["campaign"], tmp_path / "m.json", json=True) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["mode"] == "reference" and len(doc["steps"]) == 11
    assert len(doc["coefficients"]["steps"]) == 11 and doc["tilt_table"]["rows"]
    assert doc["gravity"]["g_local"] == 1.0 and doc["gravity"]["identifiable"] is False


def _bad_csv(d: Path) -> Path:
    bad = d / "bad.csv"
    bad.write_text("t_s,chamber_c,ax,ay,az\n0,25,0,0,1\n1,25,0,zero,1\n")
    return bad


def test_calibrate_bad_input_exits_2_with_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "m.json"
    assert _calibrate(_bad_csv(tmp_path), out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.csv:3" in err and "'ay'" in err
    assert not out.exists()
    few = tmp_path / "few.csv"  # parses, but 2 positions cannot determine 12 parameters
    few.write_text("t_s,chamber_c,ref_x,ref_y,ref_z,ax,ay,az\n0,25,0,0,1,0,0,1\n"
                   "1,25,1,0,0,1,0,0\n")
    assert _calibrate(few, out) == 2
    assert "few.csv" in capsys.readouterr().err and not out.exists()


def test_compensate_keeps_every_column_and_row_and_adds_cx_cy_cz(
    files: dict, tmp_path: Path
) -> None:
    src = files["campaign"].read_text().splitlines()
    # an unknown column with text, in the middle, must pass through untouched
    rows = list(csv.reader(src))
    rows[0].insert(3, "operator_note")
    for i, r in enumerate(rows[1:]):
        r.insert(3, f"note {i}, ok" if i % 2 else "")
    inp = tmp_path / "in.csv"
    with inp.open("w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)
    out = tmp_path / "out.csv"
    assert _compensate(files["model"], inp, out) == 0
    got = list(csv.reader(out.read_text().splitlines()))
    assert got[0] == rows[0] + ["cx", "cy", "cz"]
    assert [r[:-3] for r in got[1:]] == rows[1:]
    h = got[0]
    cal = np.array([[float(r[h.index(c)]) for c in ("cx", "cy", "cz")] for r in got[1:]])
    ref = np.array([[float(r[h.index(c)]) for c in ("ref_x", "ref_y", "ref_z")]
                    for r in got[1:]])
    assert np.sqrt(np.mean((cal - ref) ** 2)) < 30e-6  # g


def test_compensate_out_of_range_exits_2_unless_extrapolate(
    files: dict, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    hot = tmp_path / "hot.csv"
    hot.write_text("t_s,sensor_c,ax,ay,az,extra\n0,25.0,0.01,0.02,1.0,a\n"
                   "10,85.0,0.01,0.02,1.0,b\n")
    out = tmp_path / "out.csv"
    assert _compensate(files["model"], hot, out, raw_temperature=True) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "hot.csv:3" in err and "sensor_c" in err
    assert "--extrapolate" in err and not out.exists()
    # by default (the causal filter) the unconfirmed jump keeps its own reading
    assert _compensate(files["model"], hot, out) == 2
    assert "hot.csv:3" in capsys.readouterr().err and not out.exists()
    assert _compensate(files["model"], hot, out, extrapolate=True, raw_temperature=True) == 0
    assert out.read_text().splitlines()[2].startswith("10,85.0,0.01,0.02,1.0,b,")


def test_compensate_conditions_temperature_by_default_and_says_so(
    files: dict, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out, raw_out = tmp_path / "d.csv", tmp_path / "r.csv"
    assert _compensate(files["model"], files["campaign"], out) == 0
    said = capsys.readouterr().out
    assert "conditioned per step as calibrate did (11 step(s)" in said
    assert _compensate(files["model"], files["campaign"], raw_out, raw_temperature=True) == 0
    assert "not conditioned (--raw-temperature)" in capsys.readouterr().out
    assert out.read_text() != raw_out.read_text()
    both = tmp_path / "both.csv"
    assert _compensate(files["model"], files["campaign"], both, raw_temperature=True,
                       smooth_temperature_s=600.0) == 2
    assert "alternatives" in capsys.readouterr().err and not both.exists()


def test_compensate_bad_model_or_recording_exits_2(
    files: dict, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "out.csv"
    bad_model = tmp_path / "bad.json"
    bad_model.write_text(json.dumps({"format": "soakcal-model", "version": 99}))
    assert _compensate(bad_model, files["campaign"], out) == 2
    assert "'version'" in capsys.readouterr().err
    assert _compensate(files["model"], _bad_csv(tmp_path), out) == 2
    assert "bad.csv:3" in capsys.readouterr().err
    assert not out.exists()


def _has_service_cli() -> bool:
    return (ROOT / "service" / "cli.py").exists()


@pytest.mark.skipif(not _has_service_cli(), reason="service/cli.py not written yet")
def test_through_the_command_line(files: dict, tmp_path: Path,
                                  capsys: pytest.CaptureFixture) -> None:
    from service.cli import main

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    model = tmp_path / "m.json"
    # One real process: service/cli.py's main() as the installed `soakcal` script calls it
    # (exit status, stdout holding only the JSON). The other commands go through the same
    # main() in this process: the same parsing and exit codes, without ~1 s of imports
    # (numpy, scipy) for each.
    code = "import sys; from service.cli import main; sys.exit(main())"
    r = subprocess.run([sys.executable, "-c", code, "calibrate", str(files["campaign"]),
                        "-o", str(model), "--json", "--latitude-deg", "45", "--height-m", "0"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["method"] == "joint"
    assert doc["gravity"]["m_per_s2"] == pytest.approx(9.8061977, abs=1e-6)

    def run(*argv: str) -> tuple[int, str, str]:
        capsys.readouterr()
        try:
            rc = main(list(argv))
        except SystemExit as exit_:  # argparse's own refusals exit as the script would
            rc = exit_.code if isinstance(exit_.code, int) else 1
        out, err = capsys.readouterr()
        return rc, out, err

    rc, _, err = run("calibrate", str(files["campaign"]), "-o", str(tmp_path / "x.json"),
                     "--gravity-g", "9.81")
    assert rc == 2 and err.count("\n") == 1 and not (tmp_path / "x.json").exists()
    rc, _, err = run("export", str(model), "--format", "json-flat",
                     "-o", str(tmp_path / "flat.json"))
    assert rc == 0, err
    rc, _, err = run("export", str(files["campaign"]), "-o", str(tmp_path / "bad.h"))
    assert rc == 2 and err.count("\n") == 1 and not (tmp_path / "bad.h").exists()
    out = tmp_path / "out.csv"
    rc, said, err = run("compensate", str(model), str(files["campaign"]), "-o", str(out))
    assert rc == 0, err
    assert "conditioned per step" in said
    assert out.read_text().splitlines()[0].endswith(",cx,cy,cz")
