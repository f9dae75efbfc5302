"""The per-reading outlier statistic's tail on the second generator's nulls, pooled.

    python -m benchmarks.blind.gen2.reading_tail --cases OUT/cases [--first 300]

For each case (a null), the base model's stage-1 leave-one-reading-out statistic of every
reading (``stats.row_stats``, χ²_3 under the Gaussian noise model), on the cases whose own
tail gate (``stats.reading_tail_dof`` at its default 2 standard errors) keeps the Gaussian
null. Pooled over the cases, the share of readings above χ²_3's 95 %, 99 %, 99.9 %,
99.99 % and 99.999 % points against those levels (docs/benchmarks.md, "False alarms of the
second generator's nulls, test by test").
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

import numpy as np
from scipy import stats as sps

from calibration.discrepancy import stats
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording, read_recording

dmod = importlib.import_module("calibration.discrepancy.diagnose")  # the module


def first_stage_row_stats(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """The outlier test's first-stage statistic of every reading against the base model
    (``stats.row_stats``) and its readings' groups, as ``diagnose`` reads them."""
    pb = build_problem(rec)
    U, yw = dmod._basis(pb, [])
    e = yw - U @ (U.T @ yw)
    dof = np.sqrt(pb.m / max(pb.m - U.shape[1], 1))
    s = float(stats.robust_scale(e[:, None], dof)[0])
    t, _, g = stats.row_stats(U, e, np.zeros((pb.m, 1)), pb.row, pb.ctx.n, s, np.ones(1),
                              set(), pb.shared_t_loading)
    return t, g


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=Path, required=True)
    ap.add_argument("--first", type=int, default=300)
    a = ap.parse_args(argv)
    pooled, used = [], 0
    for p in sorted(a.cases.glob("*.csv"))[: a.first]:
        t, g = first_stage_row_stats(read_recording(p))
        if np.isfinite(stats.reading_tail_dof(t, g)):
            continue
        used += 1
        pooled.append(t)
    t = np.concatenate(pooled)
    print(f"{used} cases whose gate keeps the Gaussian null, {t.size} readings")
    print("| χ²_3 level | point | readings above | ratio |\n|---|---|---|---|")
    for q in (0.05, 0.01, 1e-3, 1e-4, 1e-5):
        x = float(sps.chi2.isf(q, 3))
        print(f"| {q:g} | {x:.2f} | {np.mean(t > x):.2e} | {np.mean(t > x) / q:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
