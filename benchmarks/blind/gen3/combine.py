"""``python -m benchmarks.blind.gen3.combine --runs OUT1 OUT2 [--replace OUTV …] --out OUT``
(issue 22): one report over several gen3 runs (e.g. two seeds); ``--replace`` puts a
variant run's cases in place of the same cases (same case seed) of the runs, so an
ablation over a subset (e.g. ``--variant t-dithered --only`` the undithered channels)
reads as the whole set with that one feature changed."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from benchmarks.blind.gen3.report import write


def read_run(out: Path) -> list[dict[str, Any]]:
    """The final (enriched) cases of a run: its results.json alarms and refusals over its
    cases.jsonl lines."""
    doc = json.loads((out / "results.json").read_text(encoding="utf-8"))
    lines = [json.loads(x) for x in (out / "cases.jsonl").read_text(encoding="utf-8")
             .splitlines() if x.strip()]
    better = {r["case_seed"]: r for r in doc["alarms"] + doc.get("refused", [])}
    return [better.get(r["case_seed"], r) | {"seed": doc["meta"]["seed"]} for r in lines]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", nargs="+", required=True)
    ap.add_argument("--replace", nargs="*", default=[])
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="")
    args = ap.parse_args(argv)
    cases: dict[int, dict[str, Any]] = {}
    for run in args.runs:
        for r in read_run(Path(run)):
            cases[r["case_seed"]] = r
    replaced = 0
    for run in args.replace:
        for r in read_run(Path(run)):
            if r["case_seed"] in cases:
                cases[r["case_seed"]] = r
                replaced += 1
    results = sorted(cases.values(), key=lambda r: (r["seed"], r["index"]))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc = write(out, results, {"title": args.title or f"{len(results)} cases",
                               "runs": args.runs, "replace": args.replace,
                               "replaced": replaced})
    print(f"false alarms {doc['false_alarms']}/{doc['judged']} "
          f"(cannot judge {doc['cannot_judge']}, {replaced} replaced); {out / 'results.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
