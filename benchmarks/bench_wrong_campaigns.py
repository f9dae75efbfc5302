"""Wrong campaign recordings a lab engineer might give: multi-position recordings with
plausible mistakes through ``soakcal calibrate``, ``compensate`` and ``diagnose`` (issues
20 and 22; docs/benchmarks.md, "Wrong campaign recordings").

    .venv/bin/python benchmarks/bench_wrong_campaigns.py [--realdata REALDATA_DIR]
        [--repo CHECKOUT] [--only NAME,...]

The base is a twin campaign (``simulate_campaign``: ADXL355-typical truth seed 3, setpoints
−20 … 60 °C in 20 °C steps, 20-min soaks, Table 1's 24 positions with reference vectors, 200
samples per mean), written by this checkout's simulator; each case writes one mistake into
a copy. With ``--realdata`` the shared OpenAXES ADXL355 log is imported (``--format
openaxes``) and fed with a few mistakes too, and so is the imucal Ferraris session
(``--format ferraris``: six faces with reference vectors). Each case runs
``calibrate --json`` (and, where
it writes a model, ``compensate`` of the unperturbed recording with it against the base
model: RMS and largest difference of cx, cy, cz in mg), ``compensate`` of the case with the
base model, and ``diagnose --json`` (its verdict and findings), with ``--repo``'s code
(default: this checkout; another checkout gives the "before" column). One markdown row per
case: exit codes and the first line a person reads.
"""

from __future__ import annotations

import argparse
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
SHOWN_CHARS = 200
Columns = dict[str, np.ndarray]


@dataclass(frozen=True)
class Case:
    name: str
    what: str
    change: Callable[[Columns], Columns]
    source: str = "twin"  # "twin" | "openaxes"


def _copy(c: Columns) -> Columns:
    return {k: v.copy() for k, v in c.items()}


def _with(c: Columns, **cols: np.ndarray) -> Columns:
    out = _copy(c)
    out.update(cols)
    return out


def _rows(c: Columns, idx: np.ndarray) -> Columns:
    return {k: v[idx] for k, v in c.items()}


def _dup_step(c: Columns) -> Columns:
    """Step 2's rows written twice, one after the other (the second copy at later times)."""
    s = c["step"]
    idx = np.flatnonzero(s == 2)
    order = np.r_[np.flatnonzero(s <= 2), idx, np.flatnonzero(s > 2)]
    out = _rows(c, order)
    span = c["t_s"][idx[-1]] - c["t_s"][idx[0]] + 15.0
    shift = np.zeros(order.size)
    k = np.flatnonzero(s <= 2).size
    shift[k:] = span
    out["t_s"] = out["t_s"] + shift
    return out


def _dup_rows(c: Columns) -> Columns:
    """Step 2's rows each written twice in place (a logger flushing its buffer twice)."""
    return _rows(c, np.repeat(np.arange(c["t_s"].size), np.where(c["step"] == 2, 2, 1)))


def _merge_steps(c: Columns) -> Columns:
    """Step 3's rows labelled step 2 (one step id over two temperatures)."""
    s = c["step"].copy()
    s[s == 3] = 2
    s[s == 4] = 3
    return _with(c, step=s)


def _same_position(c: Columns) -> Columns:
    """Positions 0 and 1 given one id (two different orientations, one label)."""
    p = c["position"].copy()
    p[p == 1] = 0
    return _with(c, position=p)


def _two_ids(c: Columns) -> Columns:
    """Position 0 labelled 0 on even steps and 30 on odd ones (one orientation, two ids)."""
    p = c["position"].copy()
    p[(p == 0) & (c["step"] % 2 == 1)] = 30
    return _with(c, position=p)


def _other_sensor(c: Columns) -> Columns:
    """Step 2's readings from another sensor: its bias 20 mg off on every axis."""
    out = _copy(c)
    m = c["step"] == 2
    for a, b in (("ax", 0.020), ("ay", -0.015), ("az", 0.020)):
        out[a][m] += b
    return out


def _five_orientations(c: Columns) -> Columns:
    """Only 5 distinct orientations, labelled as the 24 positions (each step's readings
    repeat 5 of Table 1's faces with their references)."""
    out = _copy(c)
    for s in np.unique(c["step"]):
        idx = np.flatnonzero(c["step"] == s)
        src = idx[np.arange(idx.size) % 5]
        for k in ("ax", "ay", "az", "ref_x", "ref_y", "ref_z", "sd_x", "sd_y", "sd_z"):
            rng = np.random.default_rng(int(s))
            noise = rng.normal(0, 2e-5, idx.size) if k in ("ax", "ay", "az") else 0.0
            out[k][idx] = c[k][src] + noise
    return out


def _shuffle(c: Columns) -> Columns:
    rng = np.random.default_rng(5)
    idx = np.arange(c["t_s"].size)
    j = rng.permutation(idx.size)[:10]
    idx[np.sort(j)] = j
    return _rows(c, idx)


def _f(c_col: np.ndarray) -> np.ndarray:
    return c_col * 1.8 + 32.0


TWIN_CASES: list[Case] = [
    Case("base", "none (the twin recording as it is)", _copy),
    Case("chamber_F", "chamber_c in °F", lambda c: _with(c, chamber_c=_f(c["chamber_c"]))),
    Case("sensor_F", "sensor_c in °F", lambda c: _with(c, sensor_c=_f(c["sensor_c"]))),
    Case("chamber_x10", "chamber_c ×10", lambda c: _with(c, chamber_c=c["chamber_c"] * 10)),
    Case("sensor_x10", "sensor_c ×10 (0.1 °C counts)",
         lambda c: _with(c, sensor_c=c["sensor_c"] * 10)),
    Case("swap_temps", "sensor_c and chamber_c swapped",
         lambda c: _with(c, sensor_c=c["chamber_c"], chamber_c=c["sensor_c"])),
    Case("ref_z_flip", "ref_z sign flipped", lambda c: _with(c, ref_z=-c["ref_z"])),
    Case("ref_xy_swap", "ref_x and ref_y swapped",
         lambda c: _with(c, ref_x=c["ref_y"], ref_y=c["ref_x"])),
    Case("ref_ms2", "ref_* in m/s²",
         lambda c: _with(c, ref_x=c["ref_x"] * G, ref_y=c["ref_y"] * G, ref_z=c["ref_z"] * G)),
    Case("ref_one_wrong", "one position's reference another position's (rows of position 5)",
         lambda c: _ref_one_wrong(c)),
    Case("same_position", "positions 0 and 1 given one id", _same_position),
    Case("two_ids", "one orientation given two ids (position 0 → 30 on odd steps)", _two_ids),
    Case("merge_steps", "steps 2 and 3 given one step id (readings at two temperatures)",
         _merge_steps),
    Case("dup_step", "step 2 recorded twice (its rows repeated, later times)", _dup_step),
    Case("dup_rows", "step 2's rows each written twice in place", _dup_rows),
    Case("sd_x1000", "sd_* ×1000 (mg written as g)",
         lambda c: _with(c, sd_x=c["sd_x"] * 1e3, sd_y=c["sd_y"] * 1e3, sd_z=c["sd_z"] * 1e3)),
    Case("n_is_1", "n = 1 (200-sample means)", lambda c: _with(c, n=np.ones_like(c["n"]))),
    Case("n_x1000", "n ×1000", lambda c: _with(c, n=c["n"] * 1000)),
    Case("shuffled", "10 rows out of time order", _shuffle),
    Case("other_sensor", "step 2's readings from another sensor (bias 20 mg off)",
         _other_sensor),
    Case("five_orient", "5 distinct orientations labelled as 24 positions",
         _five_orientations),
    Case("t_ms", "t_s in ms", lambda c: _with(c, t_s=c["t_s"] * 1000)),
]


def _ref_one_wrong(c: Columns) -> Columns:
    out = _copy(c)
    m = c["position"] == 5
    src = np.flatnonzero(c["position"] == 0)
    for k in ("ref_x", "ref_y", "ref_z"):
        out[k][m] = c[k][src[0]]
    return out


REAL_CASES: list[Case] = [
    Case("oa_base", "OpenAXES ADXL355 log imported (`--format openaxes`)", _copy, "openaxes"),
    Case("oa_dup", "OpenAXES: its first 5 captures written twice in place",
         lambda c: _rows(c, np.r_[np.repeat(np.arange(5), 2),
                                  np.arange(5, c["t_s"].size)]), "openaxes"),
    Case("fer_base", "imucal Ferraris session imported (`--format ferraris`: 6 faces with "
         "ref_*)", _copy, "ferraris"),
    Case("fer_ref_y_flip", "Ferraris: ref_y sign flipped", lambda c: _with(c, ref_y=-c["ref_y"]),
         "ferraris"),
    Case("fer_ref_xz_swap", "Ferraris: ref_x and ref_z swapped",
         lambda c: _with(c, ref_x=c["ref_z"], ref_z=c["ref_x"]), "ferraris"),
    Case("oa_mg_sd", "OpenAXES: sd_* ×1000", lambda c: _with(
        c, sd_x=c["sd_x"] * 1e3, sd_y=c["sd_y"] * 1e3, sd_z=c["sd_z"] * 1e3), "openaxes"),
]


def _read(path: Path) -> Columns:
    with path.open() as f:
        head = f.readline().strip().split(",")
    data = np.genfromtxt(path, delimiter=",", skip_header=1, ndmin=2)
    return {h: data[:, i] for i, h in enumerate(head)}


def _write(path: Path, c: Columns) -> Path:
    names = list(c)
    whole = {"step", "position", "n", "visit"}
    with path.open("w") as f:
        f.write(",".join(names) + "\n")
        for i in range(c[names[0]].size):
            f.write(",".join(
                "" if not np.isfinite(c[k][i]) else
                (str(int(c[k][i])) if k in whole else repr(float(c[k][i]))) for k in names)
                + "\n")
    return path


def _run(repo: Path, args: list[str]) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(repo), "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "service.cli", *args], capture_output=True,
                          text=True, env=env, cwd=repo, timeout=1800)


def _first(p: subprocess.CompletedProcess[str], work: Path) -> str:
    text = (p.stderr if p.returncode else p.stdout).strip().splitlines() or [""]
    line = text[0].replace(str(work) + "/", "")
    return line if len(line) <= SHOWN_CHARS else line[:SHOWN_CHARS] + " …"


def _comp(repo: Path, model: Path, rec: Path, out: Path) -> np.ndarray | None:
    if _run(repo, ["compensate", str(model), str(rec), "-o", str(out), "--extrapolate"]
            ).returncode:
        return None
    c = _read(out)
    return np.column_stack([c["cx"], c["cy"], c["cz"]])


def _diagnosis(p: subprocess.CompletedProcess[str]) -> str:
    if p.returncode:
        return f"diagnose {p.returncode}"
    try:
        d = json.loads(p.stdout)
    except json.JSONDecodeError:
        return "diagnose 0 (not JSON)"
    found = ", ".join(f["effect"] for f in d.get("findings", [])) or "none"
    why = d.get("cannot_judge") or d.get("reason") or ""
    return (f"diagnose 0: {d.get('verdict')}, findings {found}"
            + (f" ({str(why)[:120]})" if d.get("verdict") == "cannot judge" else ""))


def run_case(case: Case, repo: Path, bases: dict[str, tuple[Path, Path]],
             work: Path) -> tuple[str, str, str]:
    base_rec, base_model = bases[case.source]
    rec = _write(work / f"{case.name}.csv", case.change(_read(base_rec)))
    model = work / f"{case.name}.json"
    cal = _run(repo, ["calibrate", str(rec), "-o", str(model), "--json"])
    code = [f"calibrate {cal.returncode}"]
    shown = _first(cal, work) if cal.returncode else "model written"
    if cal.returncode == 0:
        ref = _comp(repo, base_model, base_rec, work / "ref.csv")
        got = _comp(repo, model, base_rec, work / "got.csv")
        if ref is not None and got is not None:
            d = (got - ref) * 1e3
            shown += (f"; on the unperturbed recording against its own model: RMS "
                      f"{np.sqrt(np.mean(d ** 2)):.3f} mg, max {np.max(np.abs(d)):.3f} mg")
    comp = _run(repo, ["compensate", str(base_model), str(rec), "-o", str(work / "c.csv"),
                       "--extrapolate"])
    code.append(f"compensate {comp.returncode}")
    if comp.returncode:
        shown += f"; compensate: {_first(comp, work)}"
    diag = _run(repo, ["diagnose", str(rec), "--json"])
    code.append(_diagnosis(diag).split(":")[0])
    if diag.returncode:
        shown += f"; diagnose: {_first(diag, work)}"
    else:
        shown += f"; {_diagnosis(diag)}"
    return case.name, ", ".join(code), shown


def _bases(repo: Path, work: Path, realdata: Path | None) -> dict[str, tuple[Path, Path]]:
    from simulators.campaign_sim import simulate_campaign
    from simulators.truth import SensorTruth

    cols = simulate_campaign(SensorTruth.adxl355_typical(3), (-20.0, 0.0, 20.0, 40.0, 60.0),
                             soak_min=20.0, seed=1003).columns  # type: ignore[union-attr]
    out = {"twin": _write(work / "twin.csv", dict(cols))}
    if realdata is not None:
        oa = work / "oa.csv"
        _run(repo, ["import", "--format", "openaxes", str(
            realdata / "openaxes-adxl355" / "log_imu9_2022-06-22_22-13-55.csv"), "-o",
            str(oa)])
        out["openaxes"] = oa
        fer = work / "fer.csv"
        _run(repo, ["import", "--format", "ferraris", str(
            realdata / "imucal-ferraris" / "example_ferraris_session.csv"), "-o", str(fer)])
        out["ferraris"] = fer
    bases = {}
    for name, rec in out.items():
        model = work / f"{name}.base.json"
        _run(repo, ["calibrate", str(rec), "-o", str(model)])
        bases[name] = (rec, model)
    return bases


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", type=Path, default=None)
    ap.add_argument("--repo", type=Path, default=Path(__file__).resolve().parents[1])
    ap.add_argument("--only", default="")
    a = ap.parse_args()
    only = {x for x in a.only.split(",") if x}
    print("| case | mistake | exit | what a person reads (first line) |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        bases = _bases(a.repo.resolve(), work, a.realdata)
        for case in TWIN_CASES + (REAL_CASES if a.realdata else []):
            if only and case.name not in only:
                continue
            name, code, line = run_case(case, a.repo.resolve(), bases, work)
            print(f"| {name} | {case.what} | {code} | {line.replace('|', '∣')} |", flush=True)


if __name__ == "__main__":
    main()
