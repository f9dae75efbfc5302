"""Where ``make test``'s time goes: per-file totals from pytest's ``--durations=0`` report.

Usage (from the repository root)::

    .venv/bin/python -m pytest -q --durations=0 [files...] > /tmp/durations.txt
    .venv/bin/python -m benchmarks.bench_suite_time /tmp/durations.txt [--top 15]

Each test's setup, call and teardown are summed into its file; the total is the sum over
all files (collection and interpreter start-up are not in pytest's report: compare it with
the run's own ``in N s`` line). Wall times: on a shared machine they move with the load, so
compare runs made under the same conditions.
"""

from __future__ import annotations

import argparse
import re
from collections import defaultdict
from pathlib import Path

# "12.34s call     tests/engine/test_crash.py::test_x[postgresql]"
_LINE = re.compile(r"^(?P<s>\d+(?:\.\d+)?)s\s+(?:setup|call|teardown)\s+(?P<id>\S+)")


def per_file_s(report: str) -> dict[str, float]:
    """Seconds per test file from the text of a ``--durations`` report."""
    totals: dict[str, float] = defaultdict(float)
    for line in report.splitlines():
        m = _LINE.match(line.strip())
        if m:
            totals[m["id"].split("::", 1)[0]] += float(m["s"])
    return dict(totals)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, help="saved output of pytest --durations=0")
    parser.add_argument("--top", type=int, default=15, help="files to list (default 15)")
    args = parser.parse_args(argv)
    totals = per_file_s(args.report.read_text(encoding="utf-8"))
    for path, s in sorted(totals.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"{s:8.1f} s  {path}")
    print(f"{sum(totals.values()):8.1f} s  all {len(totals)} files")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
