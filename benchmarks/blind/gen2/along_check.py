"""The turn check's level and the noise along the reference (issue 22).

    python -m benchmarks.blind.gen2.along_check --cases OUT/cases [--first N] [--out J]

``diagnose``'s turn check (``_turned_or_bent``) names an input-only term (``cross_coupling``,
``scale_nonlinearity``) only if its part along the reference is still needed after a turn
of the reference: an F test of the term's along-reference columns after the base model and
the turn (``turn_columns``). Here, per recording, with no term fitted (the check's model
leaves the term out), both forms of that test on both terms' columns:

* ``pooled``: the F against the residual of every entry (``stats.linear_stats``, as the
  check was to 2026-11-27);
* ``along``: ``diagnose.along_log_p``, the columns' part orthogonal (whitened) to the two
  directions across each reading's reference, against the residual there only.

On recordings where no input-only term is present (the second generator's nulls, its
turntable cases: a turn alone has no part along the reference) a calibrated test rejects
with probability equal to its level. Also printed: the whitened residual's rms along the
reference over its rms across it (after the base model and the turn), per recording.
"""

from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.turntable_geometry import _reading_across_basis, turn_columns
from calibration.discrepancy.problem import build_problem
from calibration.recording import read_recording

dg = importlib.import_module("calibration.discrepancy.diagnose")
TERMS = ("cross_coupling", "scale_nonlinearity")


def one(path: Path) -> dict:
    pb = build_problem(read_recording(path))
    if pb.mode != "reference":
        return {"case": path.stem, "skipped": "not reference mode"}
    ctx = pb.ctx
    u = ctx.input_g / np.linalg.norm(ctx.input_g, axis=1, keepdims=True)
    Xw, yw = dg._design(pb, [dg.Term("turn", float("nan"), pb.lift(turn_columns(u)))])
    U = stats.orthonormal_basis(Xw)
    e = yw - U @ (U.T @ yw)
    n = ctx.n
    C = _reading_across_basis(pb)
    c = np.cross(C[:, :, 0], C[:, :, 1])
    r = e.reshape(n, 3)
    along = float(np.sqrt(np.mean(np.sum(r * c, axis=1) ** 2)))
    across = float(np.sqrt(np.mean(np.sum(np.einsum("nak,na->nk", C, r) ** 2, axis=1) / 2)))
    out = {"case": path.stem, "readings": n, "along_over_across": round(along / across, 3)}
    for t in TERMS:
        X = BY_ID[t].regressors(ctx, 0.0)
        al = np.einsum("nak,na->nk", X, u)[:, None, :] * u[:, :, None]
        Zw = pb.whiten(pb.lift(al))
        out[t] = {"pooled": float(stats.linear_stats(U, Zw, e, e[:, None])[0] / np.log(10)),
                  "along": float(dg.along_log_p(pb, U, e, Zw) / np.log(10))}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=Path, required=True)
    ap.add_argument("--first", type=int, default=None)
    ap.add_argument("--only", default=None, help="a key effect (reads CASES/../keys)")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    files = sorted(a.cases.glob("*.csv"))
    if a.only:
        keys = a.cases.parent / "keys"
        want = a.only.split(",")
        files = [f for f in files
                 if json.loads((keys / f"{f.stem}.json").read_text())["effect"] in want]
    files = files[: a.first] if a.first else files
    rows = [one(f) for f in files]
    rows = [r for r in rows if "skipped" not in r]
    summary = {"recordings": len(rows),
               "along_over_across_q10_50_90": np.round(np.quantile(
                   [r["along_over_across"] for r in rows], [.1, .5, .9]), 3).tolist()}
    for t in TERMS:
        for form in ("pooled", "along"):
            lp = np.array([r[t][form] for r in rows])
            summary[f"{t} {form}: p<=0.05 / p<=0.005"] = [int(np.sum(lp <= np.log10(0.05))),
                                                          int(np.sum(lp <= np.log10(0.005)))]
    print(json.dumps(summary))
    if a.out:
        a.out.write_text(json.dumps({"summary": summary, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
