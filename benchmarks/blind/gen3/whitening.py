"""How much of a third-generator effect the diagnosis' whitening leaves to its test (issue 22).

``python -m benchmarks.blind.gen3.whitening --seed 1 --effect thermal_hysteresis --size 2
--only 7,14`` draws each case as ``gen3.run`` does, builds the diagnosis' linear problem
(:func:`calibration.discrepancy.problem.build_problem`) and fits the effect's catalogue
columns after the base model twice on the same data: whitened by the diagnosis' σ and by
the σ gen3 drew (sd/√n as drawn plus a hand fixture's re-seating turn,
:func:`benchmarks.blind.gen3.effects.drawn_sigma_g`). Printed per case: the columns' χ²
(the score of the effect's F test, in units of each whitening's residual variance) both
ways, and the ratio of the diagnosis' σ to the drawn σ on the axes along gravity and
across it. A χ² far below the drawn σ's is power the noise model loses before any test.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.blind.gen3.case import draw_case, simulate
from benchmarks.blind.gen3.effects import draw_effect, drawn_sigma_g
from benchmarks.blind.gen3.run import case_seed
from benchmarks.blind.gen3.writer import write_csv
from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.problem import build_problem
from calibration.recording import read_recording


def _score(X0: np.ndarray, y: np.ndarray, X: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """(χ² of the columns X after the base X0, residual variance), both whitened by w; the
    bases rank-revealing, as the diagnosis' own (stats.orthonormal_basis)."""
    Q = stats.orthonormal_basis(X0 * w[:, None])
    e = stats.project_out(Q, y * w)
    Qx = stats.orthonormal_basis(stats.project_out(Q, X * w[:, None]))
    s2 = float(e @ e) / (e.size - Q.shape[1] - Qx.shape[1])
    return float(np.sum((Qx.T @ e) ** 2)) / s2, s2


def case_figures(seed: int, index: int, effect: str, size: float) -> dict[str, float | str]:
    """One case's χ² both ways and the σ ratios (module docstring)."""
    case = draw_case(case_seed(seed, index))
    drawn, info = draw_effect(effect, case, size)
    if info.get("absorbed"):
        return {"index": index, "note": "absorbed"}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "case.csv"
        write_csv(simulate(drawn.case, drawn), path)
        rec = read_recording(path)
        with path.open(encoding="utf-8") as fh:
            rows = [{k: float(v) for k, v in r.items()
                     if k in ("sd_x", "sd_y", "sd_z", "n", "ref_x", "ref_y", "ref_z")}
                    for r in csv.DictReader(fh)]
    pb = build_problem(rec)
    eff = BY_ID[effect]
    X = pb.lift(eff.regressors(pb.ctx, eff.grid(pb.ctx)[0]))
    X0 = np.asarray(pb.X0)  # an AxisBlockDesign too (its __array__)
    sigma_drawn = drawn_sigma_g(rows, drawn.case.protocol.place_max_rad)[pb.row, pb.axis]
    chi2_diag, _ = _score(X0, pb.y, X, pb.w)
    chi2_drawn, _ = _score(X0, pb.y, X, 1.0 / sigma_drawn)
    ratio = (1.0 / pb.w) / sigma_drawn
    unit = rec.ref_g / np.linalg.norm(rec.ref_g, axis=1, keepdims=True)
    along = np.abs(unit[pb.row, pb.axis]) > 0.9
    f = drawn.case.features()
    return {"index": index, "protocol": f"{f['schedule']}×{f['visits']}, {f['plateaus']} pl, "
            f"{f['fixture']}" + (f" ≤ {f['place_max_mrad']} mrad" if f["fixture"] == "hand"
                                 else ""),
            "columns": X.shape[1], "chi2_diagnosis": chi2_diag, "chi2_drawn": chi2_drawn,
            "sigma_ratio_along": float(np.median(ratio[along])) if along.any() else float("nan"),
            "sigma_ratio_across": float(np.median(ratio[~along]))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--effect", default="thermal_hysteresis")
    ap.add_argument("--size", type=float, default=2.0)
    ap.add_argument("--only", required=True, help="comma-separated case indices")
    args = ap.parse_args(argv)
    if BY_ID[args.effect].per_reading:
        ap.error(f"{args.effect} has no columns to score (a per-reading test)")
    print("| case | protocol | columns | χ², diagnosis' σ | χ², drawn σ | σ ratio along g "
          "| σ ratio across g |")
    print("|---|---|---|---|---|---|---|")
    for index in (int(i) for i in args.only.split(",")):
        r = case_figures(args.seed, index, args.effect, args.size)
        if "note" in r:
            print(f"| {index} | {r['note']} | | | | | |")
            continue
        print(f"| {index} | {r['protocol']} | {r['columns']} | {r['chi2_diagnosis']:.1f} | "
              f"{r['chi2_drawn']:.1f} | {r['sigma_ratio_along']:.2f} | "
              f"{r['sigma_ratio_across']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
