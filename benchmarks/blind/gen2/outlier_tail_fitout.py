"""The outlier null's tail read with the largest readings fitted out: measured, not kept.

    python -m benchmarks.blind.gen2.outlier_tail_fitout --out OUT [--cases 0146,0212]
    python -m benchmarks.blind.gen2.outlier_tail_fitout --run -- GEN2_RUN_ARGS

The outlier test's null is a per-reading Student-t mixture whose ν is read from the
readings' own statistic (``diagnose._reading_dof``: ``stats.reading_tail_dof`` at its point
estimate on ``stats.row_stats`` against the current model). The estimator already counts
the ``stats.TAIL_OUTLIERS`` = 2 largest readings as outliers, but through the base fit
those readings still move their neighbours' residuals: on a gen2 case (seed 4, 0146) whose
cubic in T is nearly a fit per plateau the outlier raised its plateau's statistics and ν
fell from 23 to 5 (docs/benchmarks.md, "An outlier does not set its plateau's noise").

The variant measured here (:func:`fitout_row_stats`): the two largest readings are taken
one at a time, each the largest of the fit that has the previous one out, and given their
own columns (one per entry, as an accepted outlier term is); the other readings' statistic
is read from that fit, and the two are counted at the top, where the estimator puts its
outliers.

``--out``: for each case of a second-generator run (OUT/cases, OUT/keys; default: the
`outlier` cases at 2× whose top finding in OUT/diagnoses.json is not `outlier`; ``--first
N``: the first N cases), the first-stage ν as ``diagnose`` reads it, with the two largest
readings fitted out, with the case's two true outlier readings fitted out instead (what an
oracle that knew them would read; on a case without an outlier, the two largest), and with
those readings out and each reading's statistic divided by its plateau's median over
χ²₃'s (the tail within plateaus, without the plateau-to-plateau spread of scale).
``--run``: ``benchmarks.blind.gen2.run`` with ``diagnose``'s ν so read (the benchmark's
processes fork after the patch).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats as sps

from calibration.discrepancy import stats
from calibration.discrepancy.problem import LinearProblem, build_problem
from calibration.recording import read_recording

dmod = importlib.import_module("calibration.discrepancy.diagnose")  # the module


def _fit_out(pb: LinearProblem, U: Any, e: np.ndarray, i: int) -> tuple[Any, np.ndarray]:
    """[U, Q] and the residual with reading ``i``'s entries given their own columns: Q the
    orthonormal columns of (I − P)·I_J (BᵀB = I − U_J U_Jᵀ); (U, e) unchanged where the fit
    already determines the reading."""
    J = np.flatnonzero(pb.row == i)
    B = -(U @ U[J].T)
    B[J, np.arange(J.size)] += 1.0
    lam, V = np.linalg.eigh(B[J])
    ok = lam > 1e-6
    if not np.any(ok):
        return U, e
    Q = B @ (V[:, ok] / np.sqrt(lam[ok]))
    return np.hstack([U, Q]), e - Q @ (Q.T @ e)


def fitout_row_stats(pb: LinearProblem, U: Any, e: np.ndarray, s: float, skip: set[int],
                     rows: list[int] | None = None) -> tuple[np.ndarray, int]:
    """The per-reading statistic with readings fitted out by their own columns.

    ``rows`` None: the ``stats.TAIL_OUTLIERS`` largest (not in ``skip``), one at a time, each
    the largest of the fit with the previous ones out; else those readings. The fitted-out
    readings are returned at the largest float (the estimator's outliers)."""
    zeros, ones = np.zeros((pb.m, 1)), np.ones(1)
    t, _, g = stats.row_stats(U, e, zeros, pb.row, pb.ctx.n, s, ones, skip,
                              pb.shared_t_loading)
    out: list[int] = []
    for k in range(stats.TAIL_OUTLIERS if rows is None else len(rows)):
        if rows is None:
            free = np.array([i not in skip and i not in out for i in range(t.size)])
            cand = np.where(free & (t > 0), t, -np.inf)
            if not np.isfinite(cand.max()):
                break
            i = int(np.argmax(cand))
        else:
            i = int(rows[k])
        U, e = _fit_out(pb, U, e, i)
        out.append(i)
        t, _, g = stats.row_stats(U, e, zeros, pb.row, pb.ctx.n, s, ones, skip | set(out),
                                  pb.shared_t_loading)
    t[out] = np.finfo(float).max
    return t, g


def _keep(pb: LinearProblem, t: np.ndarray, skip: set[int]) -> np.ndarray:
    return np.array([i not in skip for i in range(pb.ctx.n)]) & (t > 0)


def reading_dof_fitout(pb: LinearProblem, U: Any, e: np.ndarray, s: float,
                       terms: list) -> tuple[float, float]:
    """``diagnose._reading_dof`` with the two largest readings fitted out (the variant)."""
    skip = {r for t in terms for r in t.rows}
    t, g = fitout_row_stats(pb, U, e, s, skip)
    keep = _keep(pb, t, skip)
    return (stats.reading_tail_dof(t[keep], g, stats.NULL_TAIL_Z),
            stats.reading_tail_dof(t[keep], g))


def case_dofs(csv: Path, rows: list[int]) -> dict[str, Any]:
    """First-stage ν of one case four ways (see the module's docstring)."""
    pb = build_problem(read_recording(csv))
    U, yw = dmod._basis(pb, [])
    e = yw - U @ (U.T @ yw)
    dof = np.sqrt(pb.m / max(pb.m - U.shape[1], 1))
    s = float(stats.robust_scale(e[:, None], dof)[0])
    t_true, g = fitout_row_stats(pb, U, e, s, set(), rows or None)  # a null: the largest two
    steps, big = pb.ctx.steps, t_true >= np.finfo(float).max
    t_plat = t_true.copy()
    for k in np.unique(steps):
        m = (steps == k) & ~big & (t_true > 0)
        if m.sum() >= 3:
            t_plat[m] = t_true[m] / np.median(t_true[m]) * sps.chi2.ppf(0.5, g)

    def nu(t: np.ndarray) -> float:
        return round(stats.reading_tail_dof(t[t > 0], g, stats.NULL_TAIL_Z), 1)

    return {"readings": pb.ctx.n, "nu_base": round(dmod._reading_dof(pb, U, e, s, [])[0], 1),
            "nu_fitout_top2": round(reading_dof_fitout(pb, U, e, s, [])[0], 1),
            "nu_fitout_true": nu(t_true), "nu_true_within_plateaus": nu(t_plat)}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--run"]:
        from benchmarks.blind.gen2 import run

        dmod._reading_dof = reading_dof_fitout
        return run.main(argv[2:] if argv[1:2] == ["--"] else argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cases", default=None)
    ap.add_argument("--first", type=int, default=None,
                    help="the first N cases of OUT/cases, whatever their effect")
    a = ap.parse_args(argv)
    if a.cases:
        cases = a.cases.split(",")
    elif a.first:
        cases = [p.stem for p in sorted((a.out / "cases").glob("*.csv"))[: a.first]]
    else:
        diags = json.loads((a.out / "diagnoses.json").read_text())
        cases = []
        for c, d in sorted(diags.items()):
            key = json.loads((a.out / "keys" / f"{c}.json").read_text())
            top = d.get("findings") or [{}]
            if (key.get("effect") == "outlier" and key.get("multiple") == 2.0
                    and top[0].get("effect") != "outlier"):
                cases.append(c)
    for c in cases:
        key = json.loads((a.out / "keys" / f"{c}.json").read_text())
        rows = (key.get("pattern") or {}).get("rows", []) if key.get("effect") == "outlier" else []
        print(json.dumps({"case": c, **case_dofs(a.out / "cases" / f"{c}.csv", rows)}),
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
