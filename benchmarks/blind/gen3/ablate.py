"""``python -m benchmarks.blind.gen3.ablate --base OUT1 OUT2 --variant NAME=DIR … `` (issue
22): for every alarm of the base runs, what each one-feature ablation of the same case
(``run --variant V --only`` the alarms) answers: ``clears``, the effects it still names, or
``·`` where the case does not have the feature the variant removes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from benchmarks.blind.gen3.combine import read_run

HAS_FEATURE = {
    "t-lsb-column": lambda f: True,
    "t-dithered": lambda f: f["t_noise_c"] / f["t_lsb_c"] < 0.6,
    "no-vibration": lambda f: bool(f["vibration_rms_mg"]),
    "gaussian-mean": lambda f: bool(f["heavy_nu"]),
    "no-reseat": lambda f: f["fixture"] == "hand",
}


def _answer(r: dict[str, Any] | None) -> str:
    if r is None:
        return "not run"
    if r.get("mismatch") is None:
        return "cannot judge"
    if not r["mismatch"]:
        return "clears"
    return "+".join(f["effect"] for f in r["findings"]) or "mismatch"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--base", nargs="+", required=True)
    ap.add_argument("--variant", nargs="+", required=True, help="NAME=DIR[,DIR…]")
    args = ap.parse_args(argv)
    base = [r for run in args.base for r in read_run(Path(run)) if r.get("mismatch")]
    variants: dict[str, dict[int, dict[str, Any]]] = {}
    for spec in args.variant:
        name, dirs = spec.split("=", 1)
        variants[name] = {r["case_seed"]: r for d in dirs.split(",") for r in read_run(Path(d))}
    print("| case | base | " + " | ".join(variants) + " |")
    print("|---|---|" + "---|" * len(variants))
    for r in base:
        cells = []
        for name, got in variants.items():
            has = HAS_FEATURE.get(name, lambda f: True)(r["features"])
            cells.append(_answer(got.get(r["case_seed"])) if has else "·")
        effects = "+".join(f["effect"] for f in r["findings"])
        print(f"| {r['seed']}/{r['index']} | {effects} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
