"""The outlier test's null against the tail a recording's largest readings show (issue 22).

    python -m benchmarks.blind.gen3.outlier_tail collect --seed S --only I,J,… --out F.npz
    python -m benchmarks.blind.gen3.outlier_tail collect --gen2 OUT [--only 0012,…] --out F.npz
    python -m benchmarks.blind.gen3.outlier_tail score F.npz [F2.npz …]

``collect`` runs ``diagnose`` on gen3 cases (drawn as ``benchmarks.blind.gen3.run`` draws
them) or on a second-generator run's case files (OUT/cases, OUT/keys) as far as the first
stage's outlier null, and keeps the per-reading statistic the tail is read from
(``diagnose._reading_dof``'s input to ``stats.reading_tail_dof``), with the case's
features. ``score`` reads, per case, ν as main reads it (two order statistics) and as
:func:`calibration.discrepancy.stats.reading_tail_dof` reads it now, and the first stage's
outlier p (the largest reading against n readings of the Student-t mixture with that ν,
Šidák over the readings, as ``diagnose`` ranks it), so estimators can be compared on the
same statistics without rerunning the diagnosis.
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
    for f in args.files:
        for r in load(Path(f)):
            t, g = r["t"], r["g"]
            nu0, nu1 = float(r["nu_reading"]), float(r["nu_entry"])
            top = " ".join(f"{v:.1f}" for v in np.sort(t)[::-1][:4])
            print(f"{r['case']:>8} n {t.size:4d} top {top:>24} ν reading {nu0:7.1f} "
                  f"entry {nu1:7.1f}  log10 p {outlier_logp(t, g, nu0) / np.log(10):7.2f} "
                  f"→ {outlier_logp(t, g, nu1) / np.log(10):7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
