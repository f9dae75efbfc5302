"""Two runs of the same blind cases side by side: what changed in the reports (issue 22).

Reads ``diagnoses.json`` of each run (both blind sets write one) and the keys of the cases
(``keys/*.json``), and prints one row per case whose verdict or top finding differs, then
the counts by kind. A "one-plateau" finding is the ``not_identifiable`` one whose first
candidate is "a change confined to step k" (calibration/discrepancy/one_step.py).

    python -m benchmarks.blind.compare_runs --before OUT_BEFORE --after OUT_AFTER
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any


def _top(d: dict[str, Any]) -> str:
    fs = d.get("findings") or []
    if not fs:
        return d.get("verdict", "error" if "error" in d else "consistent")
    f = fs[0]
    cands = (f.get("where") or {}).get("candidates") or []
    if f["effect"] == "not_identifiable" and cands:
        return "not_identifiable[" + ", ".join(c.split(" (")[0] for c in cands) + "]"
    return f["effect"]


def _keys(out: Path) -> dict[str, dict[str, Any]]:
    keys = {}
    for p in sorted((out / "keys").glob("*.json")):
        k = json.loads(p.read_text())
        keys[p.stem] = k
    return keys


def _label(k: dict[str, Any]) -> str:
    what = k.get("effect") or k.get("change") or k.get("catalogue_id") or ""
    mult = k.get("multiple")
    return f"{k.get('kind', '?')}/{what}" + (f"/{mult:g}x" if isinstance(mult, float) else "")


def compare(before: Path, after: Path) -> str:
    b = json.loads((before / "diagnoses.json").read_text())
    a = json.loads((after / "diagnoses.json").read_text())
    keys = _keys(after) or _keys(before)
    rows, counts = [], Counter()
    for c in sorted(set(a) & set(b)):
        tb, ta = _top(b[c]), _top(a[c])
        label = _label(keys.get(c, {}))
        counts[(label, "cases")] += 1
        if (tb, b[c].get("verdict")) == (ta, a[c].get("verdict")):
            continue
        counts[(label, "changed")] += 1
        rows.append(f"| {c} | {label} | {b[c].get('verdict')}: {tb} | "
                    f"{a[c].get('verdict')}: {ta} |")
    out = ["| case | key | before | after |", "|---|---|---|---|", *rows, "",
           "| key | cases | changed |", "|---|---|---|"]
    for label in sorted({lab for lab, _ in counts}):
        out.append(f"| {label} | {counts[(label, 'cases')]} | {counts[(label, 'changed')]} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", type=Path, required=True, help="OUT of the first run")
    ap.add_argument("--after", type=Path, required=True, help="OUT of the second run")
    a = ap.parse_args(argv)
    print(compare(a.before, a.after))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
