"""Which blind cases can the protocol rule of issue 10 touch (docs/diagnosis.md §11)?

    python -m benchmarks.blind.protocol_reach --cases benchmarks/blind/out/full/cases

Reads each case's recording (never its key) and counts its protocol as
``calibration.discrepancy.protocol.assess`` sees it: temperature (one way / both
ways), position order, whether ``temperature_rate`` is testable at all, and
whether a named rate or session jump could be withheld as ``not_identifiable``.
Prints the counts and the ids of the cases where it could, so only those need
diagnosing before and after a change to the rule.
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import numpy as np

from calibration.discrepancy.context import base_context
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.protocol import assess
from calibration.recording import read_recording

RIVALS = ("temperature_rate", "session_offset")


def reach(csv_path: Path) -> tuple[tuple[str, str, bool, bool], bool]:
    """(temperature, order, rate testable, withholding possible) of one recording."""
    rec = read_recording(str(csv_path))
    mode = "reference" if rec.has_reference else "norm"
    # The input only decides oblique positions, which the rule does not use.
    a = rec.ref_g if rec.has_reference else np.tile([0.0, 0.0, 1.0], (len(rec), 1))
    ctx = base_context(rec, mode, a)
    ok = {e: BY_ID[e].identifiable(ctx)[0] for e in RIVALS}
    pr = assess(ctx, identifiable=ok)
    can = pr.withheld_with("temperature_rate") is not None
    return (pr.temperature, pr.position_order, ok["temperature_rate"], can), can


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=Path, required=True, help="directory of case CSVs")
    a = ap.parse_args(argv)
    counts: Counter[tuple[str, str, bool, bool]] = Counter()
    touched: list[str] = []
    for p in sorted(a.cases.glob("*.csv")):
        key, can = reach(p)
        counts[key] += 1
        if can:
            touched.append(p.stem)
    print("n | temperature | position order | rate testable | withholding possible")
    for (temp, order, rate, can), n in sorted(counts.items()):
        print(f"{n} | {temp} | {order} | {rate} | {can}")
    print(f"cases the rule can touch ({len(touched)}): {' '.join(touched)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
