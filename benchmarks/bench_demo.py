"""Wall and CPU time of ``soakcal demo`` (the full campaign through the real stacks).

Usage: .venv/bin/python benchmarks/bench_demo.py [--repeat N] [--method soak|ramp]
                                                 [--sensors N]

Each run in a fresh directory, in this process (imports paid once, by the first run):
wall time, the process's CPU time (user + sys, every thread: the bridge's port threads and
the fits' included) and the load average before and after, so a figure taken on a shared
host says how shared it was.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import resource
import statistics
import tempfile
import time

from service.demo import run_demo


def _cpu_s() -> float:
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--method", choices=("soak", "ramp"), default="soak")
    ap.add_argument("--sensors", type=int, default=1)
    args = ap.parse_args()
    walls, cpus = [], []
    for i in range(args.repeat):
        with tempfile.TemporaryDirectory() as d:
            buf = io.StringIO()
            load0 = os.getloadavg()[0]
            t0, c0 = time.monotonic(), _cpu_s()
            with contextlib.redirect_stdout(buf):
                rc = run_demo(argparse.Namespace(out=d, fast=False, method=args.method,
                                                 sensors=args.sensors))
            walls.append(time.monotonic() - t0)
            cpus.append(_cpu_s() - c0)
            if rc != 0:
                print(buf.getvalue())
                return rc
            print(f"run {i + 1}: wall {walls[-1]:.1f} s, CPU {cpus[-1]:.1f} s (user + sys), "
                  f"load {load0:.1f} → {os.getloadavg()[0]:.1f}")
    print(f"soakcal demo --method {args.method} --sensors {args.sensors}: wall median "
          f"{statistics.median(walls):.1f} s over {len(walls)} run(s) (min {min(walls):.1f}, "
          f"max {max(walls):.1f}); CPU median {statistics.median(cpus):.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
