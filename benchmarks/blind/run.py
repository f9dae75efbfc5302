"""Blind benchmark runner: diagnose every case WITHOUT its key, then score against the keys.

    python -m benchmarks.blind.run --quick             # generate + run a small subset (< 2 min)
    python -m benchmarks.blind.run                     # full: ~500 cases, ≥ 200 nulls
    python -m benchmarks.blind.run --standin           # the trivial χ² stand-in diagnoser

Writes ``benchmarks/blind/results.md`` and ``results.json`` (``--quick``: ``results-quick.*``).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import traceback
from multiprocessing import Pool
from pathlib import Path

from benchmarks.blind import generate, score
from calibration.discrepancy.level import N_NULL
from calibration.recording import read_recording

HERE = Path(__file__).resolve().parent
REAL = "calibration.discrepancy:diagnose"
STANDIN = "benchmarks.blind.standin:diagnose"
_CFG: dict = {}


def _load(spec: str):
    mod, fn = spec.split(":")
    return getattr(importlib.import_module(mod), fn)


def _init(spec: str, n_null: int) -> None:
    _CFG["diagnose"] = _load(spec)
    _CFG["n_null"] = n_null


def diagnose_case(csv_path: str) -> tuple[str, dict]:
    """Diagnose one recording; sees only the CSV (never the keys directory)."""
    case = Path(csv_path).stem
    t0 = time.perf_counter()
    try:
        rec = read_recording(csv_path)
        d = _CFG["diagnose"](rec, seed=int(case), n_null=_CFG["n_null"])
        out = d.to_json()
        out = json.loads(out) if isinstance(out, str) else out
    except Exception as exc:  # a crash is a result too, reported per case
        out = {"error": f"{type(exc).__name__}: {exc}",
               "traceback": traceback.format_exc(limit=3)}
    out["elapsed_s"] = time.perf_counter() - t0
    return case, out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=None, help="case directory (cases/ + keys/)")
    ap.add_argument("--regenerate", action="store_true", help="regenerate the cases first")
    ap.add_argument("--standin", action="store_true", help="use the χ² stand-in diagnoser")
    ap.add_argument("--diagnose", default=None, help=f"module:function (default {REAL})")
    ap.add_argument("--n-null", type=int, default=None, help="diagnose's n_null (quick: 50)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--results", type=Path, default=None, help="results stem (no suffix)")
    a = ap.parse_args(argv)
    mode = "quick" if a.quick else "full"
    out = a.out or HERE / "out" / mode
    if a.regenerate or not (out / "cases").is_dir() or not any((out / "cases").glob("*.csv")):
        generate.main(["--out", str(out), "--jobs", str(a.jobs)] + (["--quick"] if a.quick else []))
    spec = a.diagnose or (STANDIN if a.standin else REAL)
    try:
        _load(spec)
    except (ImportError, AttributeError) as exc:
        print(f"cannot import {spec}: {exc}", file=sys.stderr)
        return 2
    n_null = a.n_null if a.n_null is not None else (50 if a.quick else N_NULL)
    csvs = sorted(str(p) for p in (out / "cases").glob("*.csv"))
    t0 = time.perf_counter()
    with Pool(a.jobs, initializer=_init, initargs=(spec, n_null)) as pool:
        diags = {}
        for i, (case, d) in enumerate(pool.imap_unordered(diagnose_case, csvs), 1):
            diags[case] = d
            if i % 50 == 0 or i == len(csvs):
                print(f"  {i}/{len(csvs)} diagnosed ({time.perf_counter() - t0:.0f} s)",
                      file=sys.stderr, flush=True)
    wall = time.perf_counter() - t0
    (out / "diagnoses.json").write_text(json.dumps(diags))
    keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
    res = score.score(keys, diags)
    res["meta"] = {"mode": mode, "diagnose": spec, "n_null": n_null, "cases": len(csvs),
                   "wall_s": wall, "jobs": a.jobs,
                   "command": "python -m benchmarks.blind.run " + " ".join(argv or sys.argv[1:])}
    header = (f"## Blind benchmark ({mode}): `{spec}`, n_null={n_null}, {len(csvs)} cases, "
              f"{wall:.0f} s on {a.jobs} cores")
    md = score.markdown(res, header)
    stem = a.results or HERE / ("results" if mode == "full" else "results-quick")
    if a.standin and a.results is None:
        stem = stem.with_name(stem.name + "-standin")
    stem.with_suffix(".md").write_text(md)
    stem.with_suffix(".json").write_text(json.dumps(res, indent=1, default=str))
    print(md)
    print(f"wrote {stem.with_suffix('.md')} and {stem.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
