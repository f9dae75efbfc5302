"""Why a tilt the oracle separates is missed: the first stage's family test, case by case.

    python -m benchmarks.blind.gen2.turn_null --out OUT [--cases 0307,0321]
                                              [--n-null 400] [--results STEM]

For every catalogue case of an earlier ``gen2.run`` in ``OUT`` whose effect is
``turntable_tilt`` or ``turntable_encoder`` (or the listed cases), the diagnosis is run
again (its own seed, ``n_null``) with two spies on its first stage:

* each family's data log10 p (Šidák-adjusted over its grid) and how many of the null
  replicates' adjusted p it reaches or beats (``count``): the family p is
  (1 + #replicates whose minimum over families is ≤ the best data p) / (n_null + 1),
  compared with α/2, so at n_null = 400 a single replicate at or below the data is a
  miss;
* ``turntable_geometry``'s test per grid value (free turn of each pose, sweep tilt, sweep
  encoder): its data log10 p and dof, and its replicates' median log10 p and share at
  p ≤ 0.01 (−0.30 and 1 % under a calibrated null).

Issue 22 (docs/benchmarks.md, "Why 2× tilts the oracle separates are missed").
"""

from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path

import numpy as np

from calibration.discrepancy.effects import turntable_geometry as tg
from calibration.recording import read_recording

D = importlib.import_module("calibration.discrepancy.diagnose")
GRID = {0: "free", 1: "tilt", 2: "encoder"}
L10 = np.log(10.0)


def first_stage(rec, seed: int, n_null: int) -> tuple[object, dict, list]:
    """The diagnosis, its first stage's tests by family, and the turn test per grid value
    ((log p, null log p, dof) in natural logs)."""
    tests: list[dict] = []
    turn: list[tuple[float, np.ndarray, int]] = []
    ev, ts = D._evaluate, tg.TurntableGeometry.test_stats

    def spy_ev(*a, **k):
        out = ev(*a, **k)
        tests.append(out)
        return out

    def spy_ts(self, pb, U, Xw, e, E):
        out = ts(self, pb, U, Xw, e, E)
        if E.shape[1] > 1:  # not the quantised channel's re-score of the data alone
            turn.append((float(out[0]), np.asarray(out[1], float).copy(), int(out[2])))
        return out

    D._evaluate, tg.TurntableGeometry.test_stats = spy_ev, spy_ts
    try:
        d = D.diagnose(rec, seed=seed, n_null=n_null)
    finally:
        D._evaluate, tg.TurntableGeometry.test_stats = ev, ts
    stage = {}
    for t in tests[:2]:  # the first stage: per-reading families, then those with columns
        stage.update(t)
    grid = len(tg.TURNTABLE_GEOMETRY.grid(D.build_problem(rec).ctx)) if turn else 0
    return d, stage, turn[:grid]


def row(case: str, key: dict, d, stage: dict, turn: list) -> str:
    st = d.stage_log[0] if d.stage_log else {}
    fams = []
    if stage:
        best = min(stage.values(), key=lambda t: t.logp_adj)
        for k, t in sorted(stage.items(), key=lambda kv: kv[1].logp_adj):
            null = np.asarray(t.logp_adj_null, float)
            c = int(np.sum(null <= best.logp_adj))
            if k == best.effect_id or c:
                fams.append(f"{k} {t.logp_adj / L10:.2f} (null min {null.min() / L10:.2f}, "
                            f"{c} ≤ data)")
    grid = "; ".join(f"{GRID[i]} {lp / L10:.2f}/{k} (null median {np.median(n) / L10:.2f}, "
                     f"{100 * np.mean(n <= -2 * L10):.0f} % ≤ 0.01)"
                     for i, (lp, n, k) in enumerate(turn)) or "not testable"
    named = ", ".join(f.effect for f in d.findings) or "—"
    return (f"| {case} | {key['effect'].removeprefix('turntable_')} | {key['multiple']:g} | "
            f"{key['protocol']} | {st.get('p_family', float('nan')):.2g} | "
            f"{'; '.join(fams) or '—'} | {grid} | {named} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cases", default=None, help="comma list (default: turntable cases)")
    ap.add_argument("--n-null", type=int, default=D.N_NULL)
    ap.add_argument("--results", type=Path, default=None)
    a = ap.parse_args(argv)
    pick = set(a.cases.split(",")) if a.cases else None
    lines = ["| case | effect | × | protocol | p_family | families at the data's p (their "
             "replicates' minimum, how many at or below the data) | turn test per grid "
             "value: log10 p/dof (replicates) | named |", "|---|---|---|---|---|---|---|---|"]
    for kp in sorted((a.out / "keys").glob("*.json")):
        key = json.loads(kp.read_text())
        if key.get("kind") != "catalogue" or (pick is not None and kp.stem not in pick) or (
                pick is None and not key["effect"].startswith("turntable")):
            continue
        rec = read_recording(a.out / "cases" / f"{kp.stem}.csv")
        d, stage, turn = first_stage(rec, int(kp.stem), a.n_null)
        lines.append(row(kp.stem, key, d, stage, turn))
        print(lines[-1], flush=True)
    if a.results:
        a.results.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
