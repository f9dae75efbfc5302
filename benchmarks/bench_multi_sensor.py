"""Several sensors per campaign: wall time of the twin with N sensors next to 1, and peak RSS.

Each configuration runs ``soakcal demo --sensors N`` (the full 11-step seed protocol:
engine, SQLite, simulated chamber/table/bridges over loopback, one fit per sensor) in
its own process, so the peak RSS (``os.wait4``'s ``ru_maxrss``) is that campaign's alone.
Also reported: the campaign's simulated duration (the rig's chamber time).

Usage: .venv/bin/python benchmarks/bench_multi_sensor.py [--sensors 1,8] [--fast]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time


def run_one(n_sensors: int, fast: bool) -> tuple[float, float, str]:
    """(wall s, peak RSS MiB, the demo's summary line) of one ``soakcal demo`` process."""
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "service.cli", "demo", "--sensors", str(n_sensors),
               "--out", out, *(["--fast"] if fast else [])]
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                text=True)
        stdout = proc.stdout.read() if proc.stdout else ""
        _pid, status, usage = os.wait4(proc.pid, 0)
        wall_s = time.monotonic() - t0
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f"demo --sensors {n_sensors} failed:\n{stdout}")
    summary = next((ln for ln in stdout.splitlines() if ln.startswith("campaign ")), "")
    return wall_s, usage.ru_maxrss / 1024.0, summary  # ru_maxrss is KiB on Linux


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", default="1,8", help="comma list of fixture sizes")
    ap.add_argument("--fast", action="store_true", help="the demo's 3-step campaign")
    args = ap.parse_args()
    print(f"{'sensors':>7} {'wall s':>7} {'wall s/sensor':>13} {'peak RSS MiB':>12} "
          f"{'simulated h':>11}")
    for n in (int(v) for v in args.sensors.split(",")):
        wall_s, rss_mib, summary = run_one(n, args.fast)
        sim = re.search(r"simulated ([0-9.]+) h", summary)
        print(f"{n:7d} {wall_s:7.1f} {wall_s / n:13.1f} {rss_mib:12.0f} "
              f"{sim.group(1) if sim else '?':>11}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
