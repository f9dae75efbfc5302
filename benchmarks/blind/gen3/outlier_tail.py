"""The outlier test's null against the tail a recording's largest readings show (issue 22).

    python -m benchmarks.blind.gen3.outlier_tail collect --seed S --only I,J,… --out F.npz
    python -m benchmarks.blind.gen3.outlier_tail collect --gen2 OUT [--only 0012,…] --out F.npz
    python -m benchmarks.blind.gen3.outlier_tail score F.npz [F2.npz …] [--cases 1/46,…]
    python -m benchmarks.blind.gen3.outlier_tail min gen2|gen3 -- RUN_ARGS

``collect`` runs ``diagnose`` on gen3 cases (drawn as ``benchmarks.blind.gen3.run`` draws
them) or on a second-generator run's case files (OUT/cases, OUT/keys) as far as the first
stage's outlier null, and keeps what its tail is read from: the per-reading statistic of
the readings not excluded, the entries (``diagnose._tail_entries``), and ν both ways
(``stats.reading_tail_dof`` on the statistic, at its point estimate: the null's ν before
issue 22's third generator; ``stats.entry_tail_dof`` on the entries: the null's ν now),
with the case's features. ``score`` gives, per case and per group of cases, the first
stage's outlier p (the largest reading against n readings of the Student-t mixture with
that ν, Šidák over the readings, as ``diagnose`` ranks it) with ν read each way, so
estimators can be compared on the same statistics without rerunning the diagnosis (an
approximation of the first stage: not the bootstrap count against the other families).
``min``: ``benchmarks.blind.gen2.run`` or ``gen3.run`` with the null's ν the heavier of the
two (:func:`reading_dof_min`; ``--jobs 1``, the patch is in-process).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from calibration.discrepancy import stats

dmod = importlib.import_module("calibration.discrepancy.diagnose")  # the module


class _Stop(BaseException):
    """Raised from the hook once the first stage's statistic is read."""


def _capture(run: Any) -> dict[str, Any] | None:
    """The first stage's tail reading under ``run()``: the per-reading statistic ``t`` of the
    readings not excluded, ``g``, the entries ``z`` the null's ν is read from, and ν read
    both ways (``nu_reading``: :func:`stats.reading_tail_dof` at its point estimate, the
    null's ν before; ``nu_entry``: :func:`stats.entry_tail_dof`)."""
    seen: list[dict[str, Any]] = []
    orig = dmod._reading_dof

    def hook(pb: Any, U: Any, e: np.ndarray, s: float, terms: list[Any]) -> tuple[float, float]:
        skip = {r for t in terms for r in t.rows}
        t_row, _, g = stats.row_stats(U, e, np.zeros((pb.m, 1)), pb.row, pb.ctx.n, s,
                                      np.ones(1), skip, pb.shared_t_loading)
        keep = np.array([i not in skip for i in range(pb.ctx.n)]) & (t_row > 0)
        z = np.array(dmod._tail_entries(pb, U, e, s, t_row, keep))
        seen.append({"t": t_row[keep].copy(), "g": int(g), "z": z,
                     "nu_reading": stats.reading_tail_dof(t_row[keep], g, stats.NULL_TAIL_Z),
                     "nu_entry": stats.entry_tail_dof(z)})
        raise _Stop

    dmod._reading_dof = hook
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            run()
    except _Stop:
        pass
    finally:
        dmod._reading_dof = orig
    return seen[0] if seen else None


def collect_gen3(seed: int, indices: list[int]) -> list[dict[str, Any]]:
    from benchmarks.blind.gen3.case import draw_case, simulate
    from benchmarks.blind.gen3.run import case_seed
    from benchmarks.blind.gen3.writer import write_csv
    from service.cli import main

    out = []
    tmp = Path(tempfile.mkdtemp())
    for i in indices:
        case = draw_case(case_seed(seed, i))
        path = tmp / f"gen3-{seed}-{i:04d}.csv"
        write_csv(simulate(case), path)
        got = _capture(lambda p=path: main(["diagnose", str(p), "--json"]))
        path.unlink()
        if got is None:
            continue
        out.append({"case": f"{seed}/{i}", **got, "features": case.features()})
        print(f"{seed}/{i}: n {got['t'].size}", file=sys.stderr, flush=True)
    tmp.rmdir()
    return out


def collect_gen2(run_out: Path, only: list[str] | None) -> list[dict[str, Any]]:
    from calibration.discrepancy import diagnose
    from calibration.recording import read_recording

    out = []
    for csv in sorted((run_out / "cases").glob("*.csv")):
        if only is not None and csv.stem not in only:
            continue
        key_path = run_out / "keys" / f"{csv.stem}.json"
        key = json.loads(key_path.read_text()) if key_path.exists() else {}
        rec = read_recording(csv)
        got = _capture(lambda r=rec, c=csv.stem: diagnose(r, seed=int(c)))
        if got is None:
            continue
        out.append({"case": csv.stem, **got, "features": key})
        print(f"{csv.stem}: n {got['t'].size}", file=sys.stderr, flush=True)
    return out


def _save(rows: list[dict[str, Any]], path: Path) -> None:
    np.savez(path, meta=json.dumps([{k: v for k, v in r.items() if k not in ("t", "z")}
                                    for r in rows], default=str),
             **{f"t{j}": r["t"] for j, r in enumerate(rows)},
             **{f"z{j}": r["z"] for j, r in enumerate(rows)})


def load(path: Path) -> list[dict[str, Any]]:
    z = np.load(path)
    meta = json.loads(str(z["meta"]))
    return [{**m, "t": z[f"t{j}"], "z": z[f"z{j}"]} for j, m in enumerate(meta)]


def outlier_logp(t: np.ndarray, g: int, nu: float) -> float:
    """log p of the largest reading, Šidák over the n readings (the first stage's rank)."""
    lp = float(stats.reading_logsf(float(np.max(t)), g, nu))
    return float(stats.sidak_log(lp, t.size))


# ν of the first stage's outlier null: as main read it (the per-reading statistic's 95th
# percentile), as diagnose reads it now (the entries' 99th percentile), and the heavier
# of the two.
ESTIMATORS = {
    "reading (before)": lambda r: float(r["nu_reading"]),
    "entries (after)": lambda r: float(r["nu_entry"]),
    "min of the two": lambda r: min(float(r["nu_reading"]), float(r["nu_entry"])),
}


def _groups(rows: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        f = r["features"]
        if "heavy_nu" in f:
            key = "gen3 t means" if f["heavy_nu"] else "gen3 Gaussian means"
        else:
            key = f"gen2 {f.get('effect')} {f.get('multiple')}x"
        out.setdefault(key, []).append(r)
    return out


def reading_dof_min(pb: Any, U: Any, e: np.ndarray, s: float,
                    terms: list[Any]) -> tuple[float, float]:
    """The variant measured, not kept: the null's ν the heavier of the entries' and the
    per-reading statistic's (both at their point estimates)."""
    nu, shown = _READING_DOF(pb, U, e, s, terms)
    skip = {r for t in terms for r in t.rows}
    t_row, _, g = stats.row_stats(U, e, np.zeros((pb.m, 1)), pb.row, pb.ctx.n, s, np.ones(1),
                                  skip, pb.shared_t_loading)
    keep = np.array([i not in skip for i in range(pb.ctx.n)]) & (t_row > 0)
    return min(nu, stats.reading_tail_dof(t_row[keep], g, stats.NULL_TAIL_Z)), shown


_READING_DOF = dmod._reading_dof


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("collect")
    c.add_argument("--seed", type=int, default=1)
    c.add_argument("--only", default=None)
    c.add_argument("--first", type=int, default=None)
    c.add_argument("--gen2", default=None)
    c.add_argument("--out", required=True)
    s = sub.add_parser("score")
    s.add_argument("files", nargs="+")
    s.add_argument("--cases", default=None, help="print these cases (seed/index or NNNN)")
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["min"]:  # python -m … outlier_tail min gen2|gen3 -- RUN_ARGS
        dmod._reading_dof = reading_dof_min
        mod = importlib.import_module(f"benchmarks.blind.{argv[1]}.run")
        return int(mod.main(argv[3:] if argv[2:3] == ["--"] else argv[2:]))
    args = ap.parse_args(argv)
    if args.cmd == "collect":
        if args.gen2:
            only = None if args.only is None else args.only.split(",")
            rows = collect_gen2(Path(args.gen2), only)
        else:
            idx = (list(range(args.first)) if args.first is not None
                   else [int(v) for v in args.only.split(",")])
            rows = collect_gen3(args.seed, idx)
        _save(rows, Path(args.out))
        return 0
    rows = [r for f in args.files for r in load(Path(f))]
    show = None if args.cases is None else set(args.cases.split(","))
    for r in rows:
        if show is not None and r["case"] in show:
            t, g = r["t"], r["g"]
            top = " ".join(f"{v:.1f}" for v in np.sort(t)[::-1][:4])
            print(f"{r['case']:>8} n {t.size:4d} top {top:>24} ν reading "
                  f"{float(r['nu_reading']):7.1f} entry {float(r['nu_entry']):7.1f}  log10 p "
                  + "  ".join(f"{outlier_logp(t, g, nu(r)) / np.log(10):7.2f}"
                              for nu in ESTIMATORS.values()))
    print(f"{'group':>28} {'estimator':>16}  p ≤ 1/401  ≤ 1 %  ≤ 5 %")
    for name, sel in _groups(rows).items():
        for est, nu in ESTIMATORS.items():
            lp = np.array([outlier_logp(r["t"], r["g"], nu(r)) for r in sel]) / np.log(10)
            print(f"{name:>28} {est:>16}  {np.sum(lp <= np.log10(1 / 401)):4d}/{len(sel)}"
                  f"  {np.sum(lp <= -2):4d}  {np.sum(lp <= np.log10(0.05)):4d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
