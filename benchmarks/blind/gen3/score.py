"""``python -m benchmarks.blind.gen3.score OUT1 OUT2 …`` (issue 22): gen3 effect runs
(``run --effect NAME``) scored case by case and summed per effect:

* ``right``: the drawn effect's id is the ``effect`` of a finding (other findings may stand
  beside it; counted in ``with_others``);
* ``not established``: a mismatch, the id not named and no other catalogue id named — only
  ``not_identifiable`` (the id among its candidates or not) or ``unexplained``;
* ``wrong``: a mismatch, the id not named, another catalogue id named;
* ``missed``: no mismatch;
* of each class, how many the report's ``protocol.not_separable`` lists the effect in
  (``listed``: the recording's protocol, by the diagnosis' own rules, cannot separate it);
* ``cannot judge`` (the gate refused) and ``absorbed`` (the base model leaves < 10⁻⁶ of the
  pattern: not drawn, not diagnosed) are listed apart and not in the totals.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from benchmarks.blind.gen3.stats import clopper_pearson

NOT_NAMES = ("not_identifiable", "unexplained")
CLASSES = ("right", "not established", "wrong", "missed")


def _candidates(f: dict[str, Any]) -> list[str]:
    where = f.get("where") or {}
    cands = where.get("candidates") if isinstance(where, dict) else None
    return [str(c) for c in cands or []]


def classify(effect: str, r: dict[str, Any]) -> str:
    """One case's class (see the module's docstring)."""
    if r.get("absorbed"):
        return "absorbed"
    if r.get("mismatch") is None:
        return "cannot judge"
    if not r["mismatch"]:
        return "missed"
    named = [f["effect"] for f in r["findings"]]
    if effect in named:
        return "right"
    if any(n not in NOT_NAMES for n in named):
        return "wrong"
    return "not established"


def describe(effect: str, r: dict[str, Any]) -> str:
    """The findings, a not_identifiable's candidates in brackets."""
    bits = []
    for f in r.get("findings", []):
        c = _candidates(f)
        bits.append(f["effect"] + (f" [{' / '.join(x[:40] for x in c)}]" if c else ""))
    return "; ".join(bits) or "–"


def read(out: Path) -> list[dict[str, Any]]:
    return [json.loads(x) for x in (out / "cases.jsonl").read_text(encoding="utf-8")
            .splitlines() if x.strip()]


def tally(results: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    out: dict[str, dict[str, int]] = {}
    for r in results:
        eff = r["effect"]["effect"]
        row = out.setdefault(eff, {k: 0 for k in (*CLASSES, "cannot judge", "absorbed",
                                                  "with_others", "listed missed",
                                                  "listed")})
        cls = classify(eff, r)
        row[cls] += 1
        if eff in r.get("not_separable", []):
            row["listed"] += 1
            row["listed missed"] += cls == "missed"
        if cls == "right" and len({f["effect"] for f in r["findings"]}) > 1:
            row["with_others"] += 1
    return out


def _ci(k: int, n: int) -> str:
    lo, hi = clopper_pearson(k, n)
    return f"{k}/{n} [{100 * lo:.0f}, {100 * hi:.0f}] %" if n else "–"


def markdown(results: list[dict[str, Any]]) -> str:
    t = tally(results)
    lines = ["| effect | right | not established | wrong | missed (listed not separable) "
             "| right (95 %) | cannot judge | absorbed |", "|---|---|---|---|---|---|---|---|"]
    tot = {k: 0 for k in CLASSES}
    for eff, row in t.items():
        n = sum(row[k] for k in CLASSES)
        for k in CLASSES:
            tot[k] += row[k]
        right = f"{row['right']}" + (f" ({row['with_others']} with others)"
                                     if row["with_others"] else "")
        lines.append(f"| `{eff}` | {right} | {row['not established']} | {row['wrong']} | "
                     f"{row['missed']} ({row['listed missed']}) | {_ci(row['right'], n)} | "
                     f"{row['cannot judge']} | "
                     f"{row['absorbed']} |")
    n = sum(tot.values())
    lines.append(f"| all | {tot['right']} | {tot['not established']} | {tot['wrong']} | "
                 f"{tot['missed']} | {_ci(tot['right'], n)} | | |")
    lines.append("")
    lines.append(f"Totals: not established {_ci(tot['not established'], n)}, wrong "
                 f"{_ci(tot['wrong'], n)}, missed {_ci(tot['missed'], n)}.")
    lines += ["", "| effect | size | case | case seed | protocol | changed | share left "
              "| class | findings |", "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        e, f = r["effect"], r["features"]
        cls = classify(e["effect"], r)
        lines.append(
            f"| `{e['effect']}` | {e['size']:g} | {r['index']} | {r['case_seed']} | "
            f"{f['schedule']}×{f['visits']}, {f['plateaus']} pl {f['order']}"
            f"{', hand' if f['fixture'] == 'hand' else ''}"
            f"{', vib' if f['vibration_rms_mg'] else ''}{', t' if f['heavy_nu'] else ''}, "
            f"T LSB {f['t_lsb_c']:g} | {', '.join(e.get('changed', {})) or '–'} | "
            f"{_share(e)} | {cls}{_listed(e, r)} | "
            f"{describe(e['effect'], r)} |")
    return "\n".join(lines) + "\n"


def _listed(e: dict[str, Any], r: dict[str, Any]) -> str:
    return " (listed)" if e["effect"] in r.get("not_separable", []) else ""


def _share(e: dict[str, Any]) -> str:
    """The share of the pattern the base model leaves (outliers: –)."""
    s = e.get("share_left")
    return "–" if s is None else f"{s:.2g}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--out", default=None, help="write the markdown here too")
    args = ap.parse_args(argv)
    results = [r for run in args.runs for r in read(Path(run)) if "effect" in r]
    text = markdown(results)
    if args.out:
        Path(args.out).write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
