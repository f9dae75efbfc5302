"""Wrong inputs a lab engineer might give: the CLI on real logs fed with plausible mistakes
(issue 20; docs/benchmarks.md, "Wrong inputs a lab engineer might give").

    .venv/bin/python benchmarks/bench_wrong_inputs.py --incl INCL.csv --flight FLIGHT.bin \
        --realdata REALDATA_DIR [--repo CHECKOUT] [--only NAME,...]

INCL.csv is the inclinometer warm-up (no header; columns 2-4 acceleration in mg, 5 die
temperature in °C, 500 Hz), FLIGHT.bin an ArduCopter DataFlash log, REALDATA_DIR the shared
recordings (bmi270-ganesh/, imu_tk-xsens/). Each case writes one mistake into a copy of a
log (in a temporary folder), runs ``soakcal import`` and, when it exits 0, ``soakcal
calibrate --json`` of the recording written, with ``--repo``'s code (default: this
checkout; another checkout gives the "before" column). It prints one markdown row per case:
exit codes, the first line a person reads (the import summary's temperature line where the
import succeeded), and for a model its mode, degree, valid range and bias change over it.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

G = 9.80665
def incl_args(temp: str = "5", rate_hz: str = "500") -> list[str]:
    """``soakcal import`` arguments of the inclinometer log, with the column read as the
    temperature and the sample rate the cases get wrong."""
    return ["--format", "csv", "--columns", f"ax=2,ay=3,az=4,temp={temp}", "--rate-hz",
            rate_hz]


INCL_ARGS = incl_args()
SHOWN_CHARS = 230


@dataclass(frozen=True)
class Case:
    name: str
    what: str  # the mistake, as the table shows it
    make: Callable[[Path, dict[str, Path]], Path]  # writes the input, returns its path
    args: list[str]


def _incl(src: dict[str, Path]) -> tuple[np.ndarray, list[str]]:
    return np.loadtxt(src["incl"], delimiter=","), src["incl"].read_text().splitlines()


def _save(path: Path, cols: list[np.ndarray], header: str | None = None) -> Path:
    np.savetxt(path, np.column_stack(cols), fmt="%.6g", delimiter=",", header=header or "",
               comments="")
    return path


def _lines(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def _blank_cells(lines: list[str], col: int, value: str) -> list[str]:
    out = list(lines)
    for i in range(100, len(out), 997):
        cells = out[i].split(",")
        cells[col] = value
        out[i] = ",".join(cells)
    return out


def _cases() -> list[Case]:
    mg = ["--accel-unit", "mg"]
    hdr = ["--format", "csv", "--columns", "temp=temp", "--rate-hz", "500", "--accel-unit",
           "mg"]
    same = lambda d, s: s["incl"]  # noqa: E731
    d_ = _incl
    return [
        Case("base", "none (the log as it is)", same, [*INCL_ARGS, *mg]),
        Case("mg_as_g", "mg declared as g", same, [*INCL_ARGS, "--accel-unit", "g"]),
        Case("ms2_as_g", "m/s² declared as g",
             lambda d, s: _save(d / "ms2.csv", [d_(s)[0][:, :1], d_(s)[0][:, 1:4] * G / 1e3,
                                                d_(s)[0][:, 4]]),
             [*INCL_ARGS, "--accel-unit", "g"]),
        Case("ms2_as_mg", "m/s² declared as mg",
             lambda d, s: _save(d / "ms2.csv", [d_(s)[0][:, :1], d_(s)[0][:, 1:4] * G / 1e3,
                                                d_(s)[0][:, 4]]),
             [*INCL_ARGS, *mg]),
        Case("counts_nosens", "counts without --counts-per-g",
             lambda d, s: _save(d / "c.csv", [d_(s)[0][:, :1], d_(s)[0][:, 1:4] * 0.256,
                                              d_(s)[0][:, 4]]),
             [*INCL_ARGS, "--accel-unit", "counts"]),
        Case("counts_x10", "counts (256/g) with --counts-per-g ×10",
             lambda d, s: _save(d / "c.csv", [d_(s)[0][:, :1], d_(s)[0][:, 1:4] * 0.256,
                                              d_(s)[0][:, 4]]),
             [*INCL_ARGS, "--accel-unit", "counts", "--counts-per-g", "2560"]),
        Case("counts_div10", "counts (256/g) with --counts-per-g ÷10",
             lambda d, s: _save(d / "c.csv", [d_(s)[0][:, :1], d_(s)[0][:, 1:4] * 0.256,
                                              d_(s)[0][:, 4]]),
             [*INCL_ARGS, "--accel-unit", "counts", "--counts-per-g", "25.6"]),
        Case("tempF_as_C", "°F declared as °C",
             lambda d, s: _save(d / "f.csv", [d_(s)[0][:, :4], d_(s)[0][:, 4] * 1.8 + 32]),
             [*INCL_ARGS, *mg]),
        Case("tempC_as_F", "°C declared as °F", same, [*INCL_ARGS, *mg, "--temp-unit", "F"]),
        Case("tempK_as_C", "K declared as °C",
             lambda d, s: _save(d / "k.csv", [d_(s)[0][:, :4], d_(s)[0][:, 4] + 273.15]),
             [*INCL_ARGS, *mg]),
        Case("tempcenti", "centi-degrees declared as °C",
             lambda d, s: _save(d / "cc.csv", [d_(s)[0][:, :4],
                                               np.round(d_(s)[0][:, 4] * 100)]),
             [*INCL_ARGS, *mg]),
        Case("temp_is_ax", "temperature mapped to the ax column (temp=2)", same,
             [*incl_args("2", "500"), *mg]),
        Case("temp_is_az", "temperature mapped to the az column (temp=4)", same,
             [*incl_args("4", "500"), *mg]),
        Case("temp_is_const", "temperature mapped to a constant column (25.0)",
             lambda d, s: _save(d / "k25.csv", [d_(s)[0][:, :4],
                                                np.full(len(d_(s)[0]), 25.0)]),
             [*INCL_ARGS, *mg]),
        Case("temp_is_col1", "temperature mapped to the counter column (temp=1)", same,
             [*incl_args("1", "500"), *mg]),
        Case("swap_xz", "x and z columns swapped",
             lambda d, s: _save(d / "sw.csv", [d_(s)[0][:, [0, 3, 2, 1, 4]]]),
             [*INCL_ARGS, *mg]),
        Case("flip_z", "z sign flipped",
             lambda d, s: _save(d / "fl.csv", [d_(s)[0][:, :3], -d_(s)[0][:, 3],
                                               d_(s)[0][:, 4]]),
             [*INCL_ARGS, *mg]),
        Case("rate_x10", "--rate-hz 5000 (×10)", same,
             [*incl_args("5", "5000"), *mg]),
        Case("rate_div10", "--rate-hz 50 (÷10)", same,
             [*incl_args("5", "50"), *mg]),
        Case("t_ms_as_s", "time column `t_ms` read as s (no --time-unit)",
             lambda d, s: _save(d / "tms.csv", [np.arange(len(d_(s)[0])) * 2.0,
                                                d_(s)[0][:, 1:5]], "t_ms,ax,ay,az,temp"),
             ["--format", "csv", "--columns", "t=t_ms,temp=temp", *mg]),
        Case("time_ms_as_s", "time column `time` in ms read as s",
             lambda d, s: _save(d / "tms.csv", [np.arange(len(d_(s)[0])) * 2.0,
                                                d_(s)[0][:, 1:5]], "time,ax,ay,az,temp"),
             ["--format", "csv", "--columns", "t=time,temp=temp", *mg]),
        Case("cut_line", "last line cut mid-number",
             lambda d, s: (d / "cut.csv").write_text("\n".join(d_(s)[1])[:-12]) and None
             or d / "cut.csv", [*INCL_ARGS, *mg]),
        Case("dup_block", "rows 40,001-60,000 written twice (no time column)",
             lambda d, s: _lines(d / "dup.csv", d_(s)[1][:60000] + d_(s)[1][40000:]),
             [*INCL_ARGS, *mg]),
        Case("dup_block_t", "a block written twice, with its time column",
             lambda d, s: _save(d / "dupt.csv", [
                 np.concatenate([np.arange(60000), np.arange(40000, 100000)]) * 2.0,
                 np.concatenate([d_(s)[0][:60000, 1:5], d_(s)[0][40000:, 1:5]])],
                 "t_ms,ax,ay,az,temp"),
             ["--format", "csv", "--columns", "t=t_ms,temp=temp", "--time-unit", "ms", *mg]),
        Case("empty_temp", "every 997th temperature cell empty",
             lambda d, s: _lines(d / "et.csv", _blank_cells(d_(s)[1], 4, "")),
             [*INCL_ARGS, *mg]),
        Case("nan_acc", "every 997th ay cell NaN",
             lambda d, s: _lines(d / "na.csv", _blank_cells(d_(s)[1], 2, "NaN")),
             [*INCL_ARGS, *mg]),
        Case("header_only", "a header and no rows",
             lambda d, s: _lines(d / "h.csv", ["ax,ay,az,temp"]), hdr),
        Case("bom", "UTF-8 BOM before the header",
             lambda d, s: (d / "bom.csv").write_text(
                 "ax,ay,az,temp\n" + "\n".join(",".join(x.split(",")[1:])
                                               for x in d_(s)[1]) + "\n",
                 encoding="utf-8-sig") and d / "bom.csv", hdr),
        Case("semicolon", "`;` separators",
             lambda d, s: _lines(d / "sc.csv", ["ax;ay;az;temp"] + [
                 ";".join(x.split(",")[1:]) for x in d_(s)[1]]), hdr),
        Case("decimal_comma", "`;` separators and decimal commas",
             lambda d, s: _lines(d / "dc.csv", ["ax;ay;az;temp"] + [
                 ";".join(x.split(",")[1:]).replace(".", ",") for x in d_(s)[1]]), hdr),
        Case("cooling", "the log reversed: the temperature going down",
             lambda d, s: _lines(d / "cool.csv", d_(s)[1][::-1]), [*INCL_ARGS, *mg]),
        Case("short_30s", "the first 30 s only",
             lambda d, s: _lines(d / "s30.csv", d_(s)[1][:15000]), [*INCL_ARGS, *mg]),
        Case("short_5s", "the first 5 s only",
             lambda d, s: _lines(d / "s5.csv", d_(s)[1][:2500]), [*INCL_ARGS, *mg]),
        Case("csv_as_dataflash", "the inclinometer CSV given as `--format dataflash`", same,
             ["--format", "dataflash"]),
        Case("flight", "ArduCopter DataFlash flight", lambda d, s: s["flight"],
             ["--format", "dataflash"]),
        Case("flight_blocks", "the flight as 5-s blocks", lambda d, s: s["flight"],
             ["--format", "dataflash", "--block-s", "5"]),
        Case("bmi_as_g", "BMI270 log (g/4 printed) declared as g",
             lambda d, s: s["bmi"], ["--format", "csv", "--columns", "temp=1,ax=2,ay=3,az=4",
                                     "--rate-hz", "50", "--accel-unit", "g",
                                     "--bad-lines", "skip"]),
        Case("bmi_ok", "BMI270 log read right (counts, --counts-per-g 0.25)",
             lambda d, s: s["bmi"], ["--format", "csv", "--columns", "temp=1,ax=2,ay=3,az=4",
                                     "--rate-hz", "50", "--accel-unit", "counts",
                                     "--counts-per-g", "0.25", "--bad-lines", "skip"]),
        Case("bmi_temp_gyro", "BMI270 log, temperature mapped to the gyro x column",
             lambda d, s: s["bmi"], ["--format", "csv", "--columns", "temp=5,ax=2,ay=3,az=4",
                                     "--rate-hz", "50", "--accel-unit", "counts",
                                     "--counts-per-g", "0.25", "--bad-lines", "skip"]),
        Case("xsens_x16", "imu_tk Xsens log, --counts-per-g 65536 (×16)",
             lambda d, s: s["xsens"], ["--format", "imu_tk", "--counts-per-g", "65536"]),
        Case("quarter_calibrate", "the imported recording at a quarter of g (another "
             "range's sensitivity), `calibrate`", same, [QUARTER, "calibrate"]),
        Case("quarter_compensate", "the base model applied to that recording, `compensate`",
             same, [QUARTER, "compensate"]),
    ]


# Cases on a recording (not an import): the base log imported, its ax, ay, az ÷ 4.
QUARTER = "@quarter"


def _quarter(repo: Path, src: dict[str, Path], work: Path) -> tuple[Path, Path]:
    """The base import as a recording at a quarter of g, and the base log's model."""
    base, model = work / "q_base.rec.csv", work / "q_base.json"
    _run(repo, ["import", *INCL_ARGS, "--accel-unit", "mg", str(src["incl"]), "-o",
                str(base)])
    _run(repo, ["calibrate", str(base), "-o", str(model)])
    with base.open() as f_in, (work / "quarter.csv").open("w", newline="") as f_out:
        rows = csv.reader(f_in)
        out = csv.writer(f_out)
        head = next(rows)
        out.writerow(head)
        axes = [head.index(c) for c in ("ax", "ay", "az")]
        for row in rows:
            for i in axes:
                row[i] = repr(float(row[i]) / 4.0)
            out.writerow(row)
    return work / "quarter.csv", model


def _run(repo: Path, args: list[str]) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(repo), "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "service.cli", *args], capture_output=True,
                          text=True, env=env, cwd=repo, timeout=900)


def _first(p: subprocess.CompletedProcess[str], work: Path,
           shown: dict[str, str] | None = None) -> str:
    """The first line a person reads, with the temporary folder and the sources' paths
    replaced by their placeholders (``shown``: path → placeholder)."""
    text = (p.stderr if p.returncode else p.stdout).strip().splitlines() or [""]
    line = text[0].replace(str(work) + "/", "").replace("soakcal import: error: ", "")
    for path, name in (shown or {}).items():
        line = line.replace(path, name)
    return line if len(line) <= SHOWN_CHARS else line[:SHOWN_CHARS] + " …"


def _model(d: dict[str, object]) -> str:
    valid = d.get("valid_c")
    change = d.get("bias_change_mg") or {}
    parts = [f"{d.get('mode')}"]
    if d.get("degree") is not None:
        parts.append(f"degree {d.get('degree')}")
    if valid:
        parts.append(f"valid {valid[0]:.2f} .. {valid[1]:.2f} °C")
    if change:
        parts.append("bias change " + " ".join(f"{k} {v:+.2f}" for k, v in change.items())
                     + " mg")
    return ", ".join(parts)


PLACEHOLDERS = {"incl": "INCL.csv", "flight": "FLIGHT.bin", "bmi": "BMI_HOT.csv",
                "xsens": "XSENS.mat"}


def run_case(case: Case, repo: Path, src: dict[str, Path], work: Path) -> tuple[str, str]:
    if case.args[0] == QUARTER:
        rec, model = _quarter(repo, src, work)
        cmd = (["calibrate", str(rec), "-o", str(work / "q.json"), "--json"]
               if case.args[1] == "calibrate" else
               ["compensate", str(model), str(rec), "-o", str(work / "q_out.csv")])
        p = _run(repo, cmd)
        if p.returncode or case.args[1] == "compensate":
            return f"{case.args[1]} {p.returncode}", _first(p, work)
        return f"{case.args[1]} 0", _model(json.loads(p.stdout))
    path = case.make(work, src)
    rec = work / f"{case.name}.rec.csv"
    imp = _run(repo, ["import", *case.args, str(path), "-o", str(rec)])
    if imp.returncode:
        lines = len(imp.stderr.splitlines())
        said = f" ({lines} lines on stderr; the first and the last shown)" if lines > 1 else ""
        last = (" … " + imp.stderr.strip().splitlines()[-1][:SHOWN_CHARS].replace(
            str(path), PLACEHOLDERS.get("incl") if path == src["incl"] else path.name)
                if lines > 1 else "")
        return f"import {imp.returncode}{said}", _first(
            imp, work, {str(src[k]): v for k, v in PLACEHOLDERS.items()}) + last
    temp = next((x.strip() for x in imp.stdout.splitlines()
                 if x.startswith("temperature (")), "no temperature")
    model = work / f"{case.name}.json"
    cal = _run(repo, ["calibrate", str(rec), "-o", str(model), "--json"])
    if cal.returncode:
        return f"import 0, calibrate {cal.returncode}", f"{temp}; {_first(cal, work)}"
    return "import 0, calibrate 0", (f"{temp}; {_model(json.loads(cal.stdout))}; "
                                     f"{_against_base(repo, src, work, model)}")


def _block_means(repo: Path, model: Path, rec: Path, out: Path) -> np.ndarray | None:
    """5-s means of ``compensate``'s cx, cy, cz (g), or None when it refuses."""
    if _run(repo, ["compensate", str(model), str(rec), "-o", str(out)]).returncode:
        return None
    with out.open() as f:
        head = f.readline().strip().split(",")
    cols = [head.index(c) for c in ("t_s", "cx", "cy", "cz")]
    data = np.loadtxt(out, delimiter=",", skiprows=1, usecols=cols, ndmin=2)
    block = (data[:, 0] // 5.0).astype(int)
    count = np.bincount(block)
    keep = count > 0
    return np.column_stack([np.bincount(block, data[:, k])[keep] / count[keep]
                            for k in (1, 2, 3)])


def _against_base(repo: Path, src: dict[str, Path], work: Path, model: Path) -> str:
    """The case's model against the base log's model, both applied to the base log: RMS
    of the difference of their compensated 5-s means about its mean, mg x / y / z (what
    the mistake changes in a compensation; the constant is not identified by a warm-up)."""
    base_rec, base_model = work / "b_base.rec.csv", work / "b_base.json"
    if not base_model.exists():
        _run(repo, ["import", *INCL_ARGS, "--accel-unit", "mg", str(src["incl"]), "-o",
                    str(base_rec)])
        _run(repo, ["calibrate", str(base_rec), "-o", str(base_model)])
    ref = _block_means(repo, base_model, base_rec, work / "b_ref.csv")
    got = _block_means(repo, model, base_rec, work / "b_got.csv")
    if ref is None or got is None or ref.shape != got.shape:
        return "on the base log: compensate refuses (another range or frame)"
    diff = (got - ref) * 1e3
    rms = np.sqrt(np.mean((diff - diff.mean(axis=0)) ** 2, axis=0))
    return "on the base log vs its own model: " + " / ".join(f"{v:.3f}" for v in rms) + " mg"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--incl", type=Path, required=True)
    ap.add_argument("--flight", type=Path, required=True)
    ap.add_argument("--realdata", type=Path, required=True)
    ap.add_argument("--repo", type=Path, default=Path(__file__).resolve().parents[1])
    ap.add_argument("--only", default="")
    a = ap.parse_args()
    src = {"incl": a.incl, "flight": a.flight,
           "bmi": a.realdata / "bmi270-ganesh" / "BMI_270_hot_test.csv",
           "xsens": a.realdata / "imu_tk-xsens" / "xsens_acc.mat"}
    only = {x for x in a.only.split(",") if x}
    print("| case | mistake | exit | what a person reads (first line) |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for case in _cases():
            if only and case.name not in only:
                continue
            code, line = run_case(case, a.repo.resolve(), src, Path(tmp))
            print(f"| {case.name} | {case.what} | {code} | {line.replace('|', '∣')} |",
                  flush=True)


if __name__ == "__main__":
    main()
