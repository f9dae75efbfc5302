"""Per case of the second generator: how ``turntable_geometry``'s test saw it (issue 22).

    python -m benchmarks.blind.gen2.turn_cases --out OUT [--n-null 200]

For every catalogue case in ``OUT`` (written by ``benchmarks.blind.gen2.run --only
turntable_tilt,turntable_encoder``): protocol, size, the first stage's family p and best
candidate, and ``turntable_geometry``'s log10 p and dof at that stage for each grid value
(free turn of each pose; sweep tilt; sweep encoder), then the name given. A markdown table
on stdout.
"""

from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path

import numpy as np

from calibration.discrepancy.effects import turntable_geometry as tg
from calibration.recording import read_recording

diagnose_mod = importlib.import_module("calibration.discrepancy.diagnose")
GRID_NAMES = {0: "free", 1: "tilt", 2: "encoder"}


def _stage0_turn_stats(rec, seed: int, n_null: int) -> tuple[object, list[tuple[float, int]]]:
    """The diagnosis and the effect's (log10 p, dof) per grid value at the first stage."""
    seen: list[tuple[float, int]] = []
    orig = tg.TurntableGeometry.test_stats

    def spy(self, pb, U, Xw, e, E):
        out = orig(self, pb, U, Xw, e, E)
        seen.append((float(out[0] / np.log(10)), int(out[2])))
        return out

    tg.TurntableGeometry.test_stats = spy
    try:
        d = diagnose_mod.diagnose(rec, seed=seed, n_null=n_null)
    finally:
        tg.TurntableGeometry.test_stats = orig
    grid = len(tg.TURNTABLE_GEOMETRY.grid(diagnose_mod.build_problem(rec).ctx))
    return d, seen[:grid]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--n-null", type=int, default=200)
    a = ap.parse_args(argv)
    print("| case | effect | × | size µrad | protocol | varied order | p_family | best | "
          "turn log10 p (dof) per grid value | named |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for kp in sorted((a.out / "keys").glob("*.json")):
        key = json.loads(kp.read_text())
        if key.get("kind") != "catalogue" or not key["effect"].startswith("turntable"):
            continue
        rec = read_recording(a.out / "cases" / f"{kp.stem}.csv")
        d, turn = _stage0_turn_stats(rec, int(kp.stem), a.n_null)
        st = d.stage_log[0] if d.stage_log else {}
        grid = "; ".join(f"{GRID_NAMES[i]} {lp:.1f} ({k})" for i, (lp, k) in enumerate(turn))
        named = ", ".join(f.effect for f in d.findings) or "—"
        print(f"| {kp.stem} | {key['effect'].removeprefix('turntable_')} | "
              f"{key['multiple']:g} | {key['magnitude']:.1f} | {key['protocol']} | "
              f"{'yes' if key['protocol_detail']['irregular'] else 'no'} | "
              f"{st.get('p_family', float('nan')):.2g} | {st.get('best', '—')} | "
              f"{grid or 'not testable'} | {named} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
