"""The twin-against-recording verdict's rates on a run of the second generator, by change.

    python -m benchmarks.blind.gen2.against_level --out OUT

Reads ``OUT/diagnoses.json`` and ``OUT/keys`` of a ``benchmarks.blind.gen2.run`` over
``against`` cases (e.g. ``--only unchanged`` with many reps). For each change (unchanged,
remount_z): the share with the verdict "mismatch" (95 % Clopper–Pearson interval) — on an
unchanged sensor that is the false-alarm rate the shared level (α) bounds as a whole — and
which of the verdict's tests fired (the coefficient shift, the refit diagnosis, the rig
check), with the smallest p each. A re-mount is right when the shift names ψ (``d_mz``) and
no bias (score.py's rule).
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any

from benchmarks.blind.score import clopper_pearson


def fired(d: dict[str, Any]) -> list[str]:
    """The verdict's tests that fired on one diagnosis (``diagnose_against``'s JSON)."""
    out = []
    if (d.get("parameter_shift") or {}).get("significant"):
        out.append("shift")
    if (d.get("refit_diagnosis") or {}).get("mismatch"):
        out.append("refit")
    if any(f.get("effect") == "thermal_lag" and "twin_tau_s" in (f.get("parameters") or {})
           for f in d.get("findings") or []):
        out.append("rig")
    return out


def remount_right(d: dict[str, Any]) -> bool:
    shift = [f for f in d.get("findings") or [] if f.get("effect") == "parameter_shift"]
    names = sorted((shift[0].get("parameters") or {}) if shift else [])
    return bool(shift) and any("_mz" in n for n in names) and not any(
        n.startswith(("d_bx", "d_by", "d_bz")) for n in names)


def summary(out: Path) -> dict[str, Any]:
    diags = json.loads((out / "diagnoses.json").read_text())
    keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
    res: dict[str, Any] = {}
    for change in ("unchanged", "remount_z"):
        cases = sorted(c for c, k in keys.items() if k.get("change") == change and c in diags)
        if not cases:
            continue
        flagged = [c for c in cases if diags[c].get("verdict") == "mismatch"]
        lo, hi = clopper_pearson(len(flagged), len(cases))
        row: dict[str, Any] = {
            "n": len(cases), "mismatch": len(flagged), "ci95": [lo, hi],
            "cannot_judge": sum(diags[c].get("verdict") == "cannot judge" for c in cases),
            "crashes": sum("error" in diags[c] for c in cases),
            "fired": dict(Counter("+".join(fired(diags[c])) for c in flagged)),
            "flagged": [{"case": c, "protocol": keys[c].get("protocol"),
                         "tests": fired(diags[c]),
                         "shift_p_family": (diags[c].get("parameter_shift") or {}).get(
                             "p_family"),
                         "findings": [f.get("effect") for f in diags[c].get("findings") or []]}
                        for c in flagged],
            "level": next((diags[c].get("level") for c in cases if diags[c].get("level")), None),
        }
        if change == "remount_z":
            row["right"] = sum(remount_right(diags[c]) for c in cases)
        res[change] = row
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    res = summary(a.out)
    for change, r in res.items():
        lo, hi = r["ci95"]
        rate = 100 * r["mismatch"] / r["n"]
        line = (f"{change}: mismatch {r['mismatch']}/{r['n']} = {rate:.1f} %"
                f" (95 % CI {100 * lo:.1f}–{100 * hi:.1f}); tests fired {r['fired']}; "
                f"cannot judge {r['cannot_judge']}; crashes {r['crashes']}")
        if "right" in r:
            line += f"; right (ψ named, no bias) {r['right']}/{r['n']}"
        print(line)
        for f in r["flagged"] if change == "unchanged" else []:
            print(f"  {f['case']} {f['protocol']}: {'+'.join(f['tests'])} "
                  f"(shift p_family {f['shift_p_family']}) {f['findings']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
