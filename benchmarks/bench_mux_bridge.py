"""N sensors on N bridges vs the same N on ONE multiplexing bridge: chamber time and wall time.

Each configuration runs the demo campaign (``service.demo._demo``: the seed's protocol,
engine, SQLite, simulated chamber and table over loopback, one fit per sensor) with the
same N serials, once with a simulated bridge per sensor and once with all of them on one
multiplexing bridge (``sim_options={"multiplexed": True}``, docs/sensor-bridge.md
"Channels"). The bridges' captures overlap across ports; on the one port the engine's
concurrent reads become one group capture (``AVG,<n>,@0,@1,…``, firmware 2.2), so the
multiplexed campaign's positions take one capture time too (N with 2.1 firmware, which
refuses the group: the third row). Each run is its own process; ``soak min`` is the
summary's soak total (the rest of the simulated time is ramps, table moves and captures).

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
import asyncio, functools, sys
from pathlib import Path
import simulators.rig
from service.demo import _demo, demo_serials, demo_spec
if {old_firmware}:  # the twin's bridge as flashed with 2.1: it answers the group ERR 1
    simulators.rig.MultiplexedBridgeDevice = functools.partial(
        simulators.rig.MultiplexedBridgeDevice, group_capture=False)
spec = demo_spec(fast={fast})
spec["sensors"] = demo_serials({n})
sys.exit(asyncio.run(_demo(Path(sys.argv[1]), spec, {{"multiplexed": {mux}}})))
"""


#: (label, multiplexed, bridge firmware without the group capture)
CONFIGS = (
    ("one per sensor", False, False),
    ("one multiplexing", True, False),
    ("one mux, fw 2.1", True, True),
)


def run_one(n_sensors: int, multiplexed: bool, old_firmware: bool, fast: bool) -> tuple[float, str]:
    """(wall s, the demo's summary line) of one campaign in its own process."""
    with tempfile.TemporaryDirectory() as out:
        code = RUN.format(fast=fast, n=n_sensors, mux=multiplexed, old_firmware=old_firmware)
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
    print(
        f"{'bridges':>22} {'sensors':>7} {'calibrated':>10} {'simulated h':>11} "
        f"{'soak min':>8} {'wall s':>7}"
    )
    for label, multiplexed, old_firmware in CONFIGS:
        wall_s, summary = run_one(args.sensors, multiplexed, old_firmware, args.fast)
        sim = re.search(r"simulated ([0-9.]+) h", summary)
        cal = re.search(r"(\d+) calibrated", summary)
        soak = re.search(r"soak total ([0-9.]+) min", summary)
        print(
            f"{label:>22} {args.sensors:7d} {cal.group(1) if cal else '?':>10} "
            f"{sim.group(1) if sim else '?':>11} {soak.group(1) if soak else '?':>8} "
            f"{wall_s:7.1f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
