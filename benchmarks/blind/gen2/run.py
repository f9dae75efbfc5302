"""Run ``diagnose`` on the second generator's cases without their keys, then score.

    python -m benchmarks.blind.gen2.run --realdata DIR [--quick] [--reps R] [--nulls N]
                                        [--n-null B] [--jobs 2] [--regenerate] [--only E,..]
                                        [--alpha A] [--out OUT] [--results STEM]
                                        [--protocols default|unseen]
                                        [--outside-set default|unseen]
                                        [--temperature-channel dithered|clean|clean-declared]
                                        [--poses]
    python -m benchmarks.blind.gen2.run --out OUT --score-only [--results STEM]

Cases with a ``given/NNNN.csv`` are twin-against-recording pairs: a model is calibrated on
the given recording (``calibration.thermal.fit_campaign``, what ``calibrate`` fits) and the
case is diagnosed against it (``diagnose --against``). Writes
``benchmarks/blind/results-gen2[-quick].md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from multiprocessing import Pool
from pathlib import Path

from benchmarks.blind.gen2 import generate, score
from calibration.discrepancy import diagnose
from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.level import ALPHA, N_NULL
from calibration.discrepancy.twin_file import Twin
from calibration.recording import read_recording
from calibration.thermal import fit_campaign

HERE = Path(__file__).resolve().parent
_CFG: dict = {}


def _init(n_null: int, alpha: float = ALPHA) -> None:
    _CFG["n_null"], _CFG["alpha"] = n_null, alpha


def diagnose_case(csv_path: str) -> tuple[str, dict]:
    case = Path(csv_path).stem
    given = Path(csv_path).parent.parent / "given" / f"{case}.csv"
    t0 = time.perf_counter()
    try:
        rec = read_recording(csv_path)
        if given.is_file():
            model = fit_campaign(read_recording(given)).model
            d = diagnose_against(rec, Twin(model), n_null=_CFG["n_null"], seed=int(case),
                                 alpha=_CFG["alpha"])
        else:
            d = diagnose(rec, seed=int(case), n_null=_CFG["n_null"], alpha=_CFG["alpha"])
        out = json.loads(d.to_json())
    except Exception as exc:  # a crash is a result too
        out = {"error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(3)}
    out["elapsed_s"] = time.perf_counter() - t0
    return case, out


def _shown_args(args: list[str]) -> str:
    """The command line as recorded: machine paths (--realdata, --out) as placeholders."""
    out, hide = [], {"--realdata": "DIR", "--out": "OUT"}
    for i, a in enumerate(args):
        out.append(hide[args[i - 1]] if i and args[i - 1] in hide else a)
    return " ".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None,
                    help="directory of the shared real recordings (or SOAKCAL_REALDATA)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--nulls", type=int, default=None)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--regenerate", action="store_true")
    ap.add_argument("--n-null", type=int, default=None, help="diagnose's n_null (quick: 100)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--alpha", type=float, default=ALPHA,
                    help="diagnose's alpha (the verdict's level; 2/alpha - 1 replicates at least "
                         "for the bootstrap to resolve alpha/2)")
    ap.add_argument("--only", default=None,
                    help="generate only these effects/kinds (see generate --only)")
    ap.add_argument("--protocols", choices=("default", "unseen"), default="default",
                    help="protocol family of generated cases (see generate --protocols)")
    ap.add_argument("--outside-set", choices=("default", "unseen"), default="default",
                    help="outside effects of generated cases (see generate --outside-set)")
    ap.add_argument("--temperature-channel", choices=("dithered", "clean", "clean-declared"),
                    default="dithered",
                    help="sensor_c channel of generated cases (see generate "
                         "--temperature-channel)")
    ap.add_argument("--poses", action="store_true",
                    help="the recordings give the table's commanded pose per reading (generate)")
    ap.add_argument("--results", type=Path, default=None, help="results stem (no suffix)")
    ap.add_argument("--score-only", action="store_true",
                    help="score OUT/diagnoses.json of an earlier run again (no diagnosis)")
    a = ap.parse_args(argv)
    mode = "quick" if a.quick else "full"
    out = a.out or HERE / "out" / mode
    if a.score_only:
        return _score_again(out, a.results)
    if a.regenerate or not any((out / "cases").glob("*.csv")):
        gen = ["--out", str(out), "--reps", str(a.reps), "--seed", str(a.seed),
               "--jobs", str(a.jobs)]
        gen += (["--realdata", a.realdata] if a.realdata else []) + (["--quick"] if a.quick
                                                                    else [])
        gen += ["--nulls", str(a.nulls)] if a.nulls is not None else []
        gen += ["--only", a.only] if a.only else []
        gen += ["--protocols", a.protocols] if a.protocols != "default" else []
        gen += ["--outside-set", a.outside_set] if a.outside_set != "default" else []
        gen += (["--temperature-channel", a.temperature_channel]
                if a.temperature_channel != "dithered" else [])
        gen += ["--poses"] if a.poses else []
        if generate.main(gen):
            return 2
    n_null = a.n_null if a.n_null is not None else (100 if a.quick else N_NULL)
    csvs = sorted(str(p) for p in (out / "cases").glob("*.csv"))
    t0 = time.perf_counter()
    diags = {}
    with Pool(a.jobs, initializer=_init, initargs=(n_null, a.alpha)) as pool:
        for i, (case, d) in enumerate(pool.imap_unordered(diagnose_case, csvs), 1):
            diags[case] = d
            if i % 25 == 0 or i == len(csvs):
                print(f"  {i}/{len(csvs)} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    wall = time.perf_counter() - t0
    (out / "diagnoses.json").write_text(json.dumps(diags))
    keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
    res = score.score(keys, diags)
    res["meta"] = {"mode": mode, "n_null": n_null, "cases": len(csvs), "wall_s": wall,
                   "command": "python -m benchmarks.blind.gen2.run " + _shown_args(
                       argv if argv is not None else sys.argv[1:])}
    md = score.markdown(res, f"## Second generator ({mode}): n_null={n_null}, {len(csvs)} "
                             f"cases, {wall:.0f} s on {a.jobs} processes")
    stem = a.results or HERE.parent / ("results-gen2" if mode == "full" else
                                       "results-gen2-quick")
    stem.with_suffix(".md").write_text(md)
    stem.with_suffix(".json").write_text(json.dumps(res, indent=1, default=str))
    print(md)
    return 0


def _score_again(out: Path, stem: Path | None) -> int:
    """Score an earlier run's diagnoses again (e.g. after the scorer gained a column)."""
    diags = json.loads((out / "diagnoses.json").read_text())
    keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
    res = score.score(keys, diags)
    md = score.markdown(res, f"## Second generator, scored again: {len(diags)} cases")
    if stem is not None:
        stem.with_suffix(".md").write_text(md)
        stem.with_suffix(".json").write_text(json.dumps(res, indent=1, default=str))
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
