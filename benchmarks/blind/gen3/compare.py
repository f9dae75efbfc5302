"""``python -m benchmarks.blind.gen3.compare --before OUT1 OUT2 … --after OUTA OUTB …
[--replace OUTR …]`` (issue 22): two builds' runs of the same gen3 nulls (the same seeds, so
the same case seeds) compared case by case (``--replace``: a run over some cases of the
"after" build, ``run --only``, in place of the same cases of its runs): false alarms with
their Clopper–Pearson 95 % intervals, the alarms each side has alone, the refusals that
changed, and the rates with and without slow vibration. Prints markdown."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from scipy.stats import beta

from benchmarks.blind.gen3.combine import read_run


def clopper_pearson(k: int, n: int) -> tuple[float, float]:
    lo = 0.0 if k == 0 else float(beta.ppf(0.025, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(0.975, k + 1, n - k))
    return lo, hi


def rate(k: int, n: int) -> str:
    if n == 0:
        return "–"
    lo, hi = clopper_pearson(k, n)
    return f"{k}/{n} = {100 * k / n:.1f} % ({100 * lo:.1f}–{100 * hi:.1f})"


def _cases(runs: list[str]) -> dict[int, dict[str, Any]]:
    return {r["case_seed"]: r for run in runs for r in read_run(Path(run))}


def _name(r: dict[str, Any]) -> str:
    return f"{r['seed']}/{r['index']}"


def _said(r: dict[str, Any] | None) -> str:
    if r is None:
        return "not run"
    if r.get("mismatch") is None:
        return "cannot judge"
    if not r["mismatch"]:
        return "–"
    return "; ".join(f"{f['effect']} ({f.get('test', '?')}, "
                     f"{f.get('p_family') or f.get('p_value')})"
                     for f in r["findings"]) or "mismatch"


def _features(r: dict[str, Any]) -> str:
    f = r["features"]
    parts = [f"{f['schedule']}×{f['visits']}", f"T LSB {f['t_lsb_c']} ({f['t_dither']:.2f})"]
    if f.get("heavy_nu"):
        parts.append(f"t ν {f['heavy_nu']:.1f}")
    if f.get("vibration_rms_mg"):
        parts.append(f"vib {f['vibration_rms_mg']:.2f} mg")
    if f.get("raw_lsb_ug"):
        parts.append(f"LSB {f['raw_lsb_ug']:g} µg")
    if f.get("fixture") == "hand":
        parts.append(f"hand ≤ {f['place_max_mrad']:.2f} mrad")
    return ", ".join(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--before", nargs="+", required=True)
    ap.add_argument("--after", nargs="+", required=True)
    ap.add_argument("--replace", nargs="*", default=[])
    args = ap.parse_args(argv)
    before, after = _cases(args.before), _cases(args.after)
    for seed, r in _cases(args.replace).items():
        if seed in after:
            after[seed] = r
    common = sorted(set(before) & set(after), key=lambda c: (before[c]["seed"],
                                                             before[c]["index"]))
    print(f"cases in both: {len(common)} (before only {len(set(before) - set(after))}, "
          f"after only {len(set(after) - set(before))})\n")
    print("| | before | after |\n|---|---|---|")
    for label, keep in (("all", lambda r: True),
                        ("slow vibration", lambda r: bool(r["features"]["vibration_rms_mg"])),
                        ("no vibration", lambda r: not r["features"]["vibration_rms_mg"])):
        cells = []
        for side in (before, after):
            rs = [side[c] for c in common if keep(before[c])]
            judged = [r for r in rs if r.get("mismatch") is not None]
            cells.append(rate(sum(bool(r["mismatch"]) for r in judged), len(judged)))
        print(f"| false alarms, {label} | {cells[0]} | {cells[1]} |")
    print(f"| cannot judge | {sum(before[c].get('mismatch') is None for c in common)} | "
          f"{sum(after[c].get('mismatch') is None for c in common)} |")
    print("\n| case | features | before | after |\n|---|---|---|---|")
    for c in common:
        b, a = before[c], after[c]
        if bool(b.get("mismatch")) or bool(a.get("mismatch")) or \
                (b.get("mismatch") is None) != (a.get("mismatch") is None):
            print(f"| {_name(b)} | {_features(b)} | {_said(b)} | {_said(a)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
