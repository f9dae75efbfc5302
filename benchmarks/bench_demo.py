"""Wall time of ``soakcal demo`` (the full 11-step campaign through the real stacks).

Usage: .venv/bin/python benchmarks/bench_demo.py [--repeat N]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import tempfile
import time

from service.demo import run_demo


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    walls = []
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as d:
            buf = io.StringIO()
            t0 = time.monotonic()
            with contextlib.redirect_stdout(buf):
                rc = run_demo(argparse.Namespace(out=d, fast=False))
            walls.append(time.monotonic() - t0)
            if rc != 0:
                print(buf.getvalue())
                return rc
    print(f"soakcal demo wall time: median {statistics.median(walls):.1f} s "
          f"over {len(walls)} run(s) (min {min(walls):.1f}, max {max(walls):.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
