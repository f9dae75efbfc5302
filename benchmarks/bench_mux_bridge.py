"""N sensors on N bridges vs the same N on ONE multiplexing bridge: chamber time and wall time.

Each configuration runs the demo campaign (``service.demo._demo``: the seed's protocol,
engine, SQLite, simulated chamber and table over loopback, one fit per sensor) with the
same N serials, once with a simulated bridge per sensor and once with all of them on one
multiplexing bridge (``sim_options={"multiplexed": True}``, docs/sensor-bridge.md
"Channels"). The bridges' captures overlap across ports but queue on one port (one command
in flight), so the multiplexed campaign's positions take N capture times instead of one.
Each run is its own process.

Usage: .venv/bin/python benchmarks/bench_mux_bridge.py [--sensors 8] [--fast]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time

RUN = """
import asyncio, sys
from pathlib import Path
from service.demo import _demo, demo_serials, demo_spec
spec = demo_spec(fast={fast})
spec["sensors"] = demo_serials({n})
sys.exit(asyncio.run(_demo(Path(sys.argv[1]), spec, {{"multiplexed": {mux}}})))
"""


def run_one(n_sensors: int, multiplexed: bool, fast: bool) -> tuple[float, str]:
    """(wall s, the demo's summary line) of one campaign in its own process."""
    with tempfile.TemporaryDirectory() as out:
        code = RUN.format(fast=fast, n=n_sensors, mux=multiplexed)
        t0 = time.monotonic()
        proc = subprocess.run(
            [sys.executable, "-c", code, out], capture_output=True, text=True, check=False
        )
        wall_s = time.monotonic() - t0
    if proc.returncode != 0:
        raise SystemExit(
            f"campaign failed (multiplexed={multiplexed}):\n{proc.stdout}\n{proc.stderr}"
        )
    return wall_s, next(ln for ln in proc.stdout.splitlines() if ln.startswith("campaign "))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", type=int, default=8)
    ap.add_argument("--fast", action="store_true", help="the demo's 3-step campaign")
    args = ap.parse_args()
    print(f"{'bridges':>22} {'sensors':>7} {'calibrated':>10} {'simulated h':>11} {'wall s':>7}")
    for multiplexed in (False, True):
        wall_s, summary = run_one(args.sensors, multiplexed, args.fast)
        sim = re.search(r"simulated ([0-9.]+) h", summary)
        cal = re.search(r"(\d+) calibrated", summary)
        label = "one multiplexing" if multiplexed else "one per sensor"
        print(
            f"{label:>22} {args.sensors:7d} {cal.group(1) if cal else '?':>10} "
            f"{sim.group(1) if sim else '?':>11} {wall_s:7.1f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
