"""A run of the unseen protocol family (``run.py --protocols unseen``) per variant.

    python -m benchmarks.blind.gen2.by_variant --out OUT

Reads ``OUT/keys`` and ``OUT/diagnoses.json`` (as ``run.py --score-only`` does) and prints,
per variant (the first field of the protocol's name, unseen.py): nulls flagged with their
95 % Clopper–Pearson interval and the tests that fired; catalogue cases at 2× named right,
reported not separable with the key among the candidates, or missed; chamber-only nulls on a
slow die (keyed ``slow_die``: a thermal lag, generate.py) by their size against the lag's
minimum detectable one.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

from benchmarks.blind.gen2 import score


def variant_of(key: dict) -> str:
    return str(key["protocol"]).split("/")[0]


def tables(keys: dict[str, dict], diags: dict[str, dict]) -> str:
    nulls: dict[str, list[str]] = defaultdict(list)
    cat: dict[str, list[tuple[str, dict]]] = defaultdict(list)
    for c, k in sorted(keys.items()):
        if k["kind"] == "null":
            nulls[variant_of(k)].append(c)
        elif k["kind"] == "catalogue" and k["multiple"] == 2.0:
            cat[variant_of(k)].append((c, k))
    out = ["| variant | nulls flagged | 95 % interval | tests fired |", "|---|---|---|---|"]
    for v, cs in sorted(nulls.items()):
        fa = [c for c in cs if score._flagged(diags[c])]
        r = score._rate(len(fa), len(cs))
        fired = score._by_test(fa, diags)
        out.append(f"| {v} | {len(fa)}/{len(cs)} | {100 * r['ci95'][0]:.1f}–"
                   f"{100 * r['ci95'][1]:.1f} % | "
                   f"{', '.join(f'{t} {n}' for t, n in fired.items()) or '–'} |")
    if cat:
        out += ["", "| variant | catalogue at 2×: right / not separable (key a candidate) / "
                "other / n | missed or misnamed (effect: top finding) |", "|---|---|---|"]
        for v, rows in sorted(cat.items()):
            right = sep = 0
            other = []
            for c, k in rows:
                top = (score._named(diags[c]) or [None])[0]
                if top == k["catalogue_id"]:
                    right += 1
                elif score._not_separable(diags[c], k["catalogue_id"]):
                    sep += 1
                else:
                    other.append(f"{k['effect']}: {top}")
            out.append(f"| {v} | {right} / {sep} / {len(other)} / {len(rows)} | "
                       f"{'; '.join(other) or '–'} |")
    slow = [(c, k) for c, k in sorted(keys.items()) if k["kind"] == "slow_die"]
    if slow:
        out += ["", "| slow die (thermal_lag at τ/m*) | n | flagged | named thermal_lag | "
                "not separable, thermal_lag a candidate | other top finding |",
                "|---|---|---|---|---|---|"]
        for label, sel in (("≥ 1× detectable", lambda x: x >= 1.0),
                           ("< 1× detectable", lambda x: x < 1.0)):
            rows = [(c, k) for c, k in slow if sel(k["multiple"])]
            tops = [(score._named(diags[c]) or [None])[0] for c, _ in rows]
            other = [t for t in tops if t not in (None, "thermal_lag", "not_identifiable")]
            out.append(f"| {label} | {len(rows)} | "
                       f"{sum(score._flagged(diags[c]) for c, _ in rows)} | "
                       f"{tops.count('thermal_lag')} | "
                       f"{sum(score._not_separable(diags[c], 'thermal_lag') for c, _ in rows)}"
                       f" | {', '.join(sorted(set(other), key=str)) or '–'} "
                       f"({len(other)}) |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    diags = json.loads((a.out / "diagnoses.json").read_text())
    keys = {p.stem: json.loads(p.read_text()) for p in (a.out / "keys").glob("*.json")}
    print(tables(keys, diags), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
