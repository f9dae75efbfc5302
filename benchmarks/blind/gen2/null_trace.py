"""Trace the family test's first stage on the second generator's nulls: each family's own p.

    python -m benchmarks.blind.gen2.null_trace --cases OUT/cases [--only 0221,0248]
                                               [--first N] [--out trace.json]

For each case (a null: no effect), ``diagnose`` is run as the benchmark runs it (seed = the
case number, the default B and α) with its stage-1 ``_evaluate`` calls recorded. Per
family: the data's Šidák-adjusted log10 p, its own null's 1/(B+1), 1 % and 5 % quantiles and
smallest value, and its **own** rank p (1 + #{replicates at or below the data}) / (B + 1);
the union's count (replicates whose minimum over families is at or below the data's
minimum) and the reading tail ν the outlier family's null used. Under a null each family's
own rank p is uniform when its replicates have the data's law, so the share of nulls at
own p ≤ 1/(B+1), ≤ 1 % and ≤ 5 % per family tells which family's null is too light
(docs/benchmarks.md, "False alarms of the second generator's nulls, test by test").
"""

from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from calibration.recording import read_recording

# The module (the package's ``diagnose`` attribute is the function of that name).
dmod = importlib.import_module("calibration.discrepancy.diagnose")
LOG10 = np.log(10.0)


def trace_case(csv_path: Path) -> dict[str, Any]:
    """Stage-1 per-family figures of one case (see the module's docstring)."""
    calls: list[dict[str, Any]] = []
    nus: list[float] = []
    orig_eval, orig_dof = dmod._evaluate, dmod._reading_dof

    def rec_eval(*a: Any, **k: Any) -> dict:
        out = orig_eval(*a, **k)
        calls.append(out)
        return out

    def rec_dof(*a: Any, **k: Any) -> tuple[float, float]:
        nu = orig_dof(*a, **k)  # (the null's ν, the ν resolved at 2 standard errors)
        nus.append(float(nu[0]))
        return nu

    dmod._evaluate, dmod._reading_dof = rec_eval, rec_dof
    try:
        d = dmod.diagnose(read_recording(csv_path), seed=int(csv_path.stem))
    finally:
        dmod._evaluate, dmod._reading_dof = orig_eval, orig_dof
    out: dict[str, Any] = {"case": csv_path.stem, "mismatch": bool(d.mismatch),
                           "findings": [f.effect for f in d.findings],
                           "scan_p": float(d.unexplained.get("p_value", float("nan"))),
                           "nu": nus[0] if nus else None}
    if len(calls) < 2:
        return out
    tests = {**calls[0], **calls[1]}
    if not tests:
        return out
    fam: dict[str, Any] = {}
    lmin = np.min(np.vstack([t.logp_adj_null for t in tests.values()]), axis=0)
    b = lmin.size
    for k, t in tests.items():
        nul = np.asarray(t.logp_adj_null, float)
        fam[k] = {"log10_p": float(t.logp_adj / LOG10),
                  "own_p": float((1 + np.sum(nul <= t.logp_adj)) / (b + 1)),
                  "null_min": float(nul.min() / LOG10),
                  "null_q1": float(np.quantile(nul, 0.01) / LOG10),
                  "null_q5": float(np.quantile(nul, 0.05) / LOG10),
                  "n_union_min": int(np.sum(np.argmin(np.vstack(
                      [u.logp_adj_null for u in tests.values()]), axis=0)
                      == list(tests).index(k)))}
    best = min(tests.values(), key=lambda t: t.logp_adj)
    out.update(best=best.effect_id, count=int(np.sum(lmin <= best.logp_adj)), B=b,
               union_q1=float(np.quantile(lmin, 0.01) / LOG10),
               union_min=float(lmin.min() / LOG10), families=fam)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=Path, required=True)
    ap.add_argument("--only", default=None)
    ap.add_argument("--first", type=int, default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    paths = sorted(args.cases.glob("*.csv"))
    if args.only:
        want = set(args.only.split(","))
        paths = [p for p in paths if p.stem in want]
    if args.first:
        paths = paths[: args.first]
    res = []
    for p in paths:
        r = trace_case(p)
        res.append(r)
        if args.only:
            print(json.dumps(r, indent=1))
    if args.out:
        args.out.write_text(json.dumps(res))
    print(summary(res))
    return 0


def summary(res: list[dict[str, Any]]) -> str:
    """Per family: nulls tested, and the share at own p ≤ 1/(B+1), ≤ 1 %, ≤ 5 %."""
    rows: dict[str, list[float]] = {}
    for r in res:
        for k, f in r.get("families", {}).items():
            rows.setdefault(k, []).append(f["own_p"])
    lines = ["| family | nulls | own p ≤ 1/(B+1) | ≤ 1 % | ≤ 5 % |", "|---|---|---|---|---|"]
    for k in sorted(rows):
        p = np.array(rows[k])
        b = max((r.get("B", 400) for r in res), default=400)
        lines.append(f"| {k} | {p.size} | {np.sum(p <= 1.5 / (b + 1))} | "
                     f"{np.sum(p <= 0.01)} ({100 * np.mean(p <= 0.01):.1f} %) | "
                     f"{np.sum(p <= 0.05)} ({100 * np.mean(p <= 0.05):.1f} %) |")
    cnt = [r["count"] for r in res if "count" in r]
    lines.append(f"\nunion count = 0 (family test at 1/(B+1)): {sum(c == 0 for c in cnt)}"
                 f" of {len(cnt)}")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
