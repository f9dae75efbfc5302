"""The project set's ``turntable_geometry`` cases diagnosed as recorded and with each
plateau's positions visited in another order (issue 22).

    python -m benchmarks.blind.order_shuffled [--effect turntable_geometry] [--n-null 400]

Why: the project generator's protocols visit Table 1 (+ cube14) in the same order on every
plateau, where a turn of each pose is also a settling at each time within the plateaus and
``turntable_geometry`` is not identifiable (``TurntableGeometry.identifiable``). Permuting
the time stamps within each plateau (a seeded order per plateau; the readings' values are
unchanged, the soaks are settled) asks whether the diagnosis names the tilt where the
protocol separates it. Builds the cases of ``generate.plan`` (seed 1, 3 repeats) for the
effect, in a temporary directory; prints one line per case and both tallies.
"""

from __future__ import annotations

import argparse
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from benchmarks.blind import generate
from calibration.discrepancy import diagnose
from calibration.recording import Recording, read_recording


def shuffled(rec: Recording, seed: int) -> Recording:
    """The recording with the time stamps permuted within each plateau (rows re-sorted)."""
    cols = {k: v.copy() for k, v in rec.columns.items()}
    rng = np.random.default_rng(seed)
    for s in np.unique(cols["step"]):
        m = np.flatnonzero(cols["step"] == s)
        cols["t_s"][m] = cols["t_s"][m][rng.permutation(m.size)]
    order = np.lexsort((cols["t_s"], cols["step"]))
    return Recording.from_columns({k: v[order] for k, v in cols.items()})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", default="turntable_geometry")
    ap.add_argument("--n-null", type=int, default=400)
    a = ap.parse_args(argv)
    specs = [s for s in generate.plan(False, 3, 200, 1)
             if s.effect == a.effect and s.kind == "effect"]
    tally: dict[str, Counter] = {"as recorded": Counter(), "order per plateau": Counter()}
    with tempfile.TemporaryDirectory() as tmp:
        for s in specs:
            generate.build(s, Path(tmp))
            rec = read_recording(Path(tmp) / "cases" / f"{s.case}.csv")
            tops = []
            for label, r in (("as recorded", rec), ("order per plateau", shuffled(rec, 7))):
                d = diagnose(r, seed=int(s.case), n_null=a.n_null)
                top = d.findings[0].effect if d.findings else "(none)"
                tally[label][(s.multiple, top)] += 1
                tops.append(top)
            print(f"{s.case} {s.multiple:>4}×  as recorded: {tops[0]:<20} "
                  f"order per plateau: {tops[1]}", flush=True)
    for label, c in tally.items():
        print(label, dict(sorted(c.items())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
