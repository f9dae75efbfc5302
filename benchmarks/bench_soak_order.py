"""Table move time of one step's sweep: Table 1 order vs least travel vs seeded random orders.

Move times by the trapezoidal profile of calibration.position_order (the simulated
table's 20 °/s, 40 °/s² unless given), from the home pose (all axes 0°), for the
positions of a schedule mapped to table angles by drivers.geometry. Pure
arithmetic, < 1 s.

``--demo``: the engine end to end instead. One ``soakcal demo --position-order X``
process per order (the full seed protocol through the engine and the twin): the
campaign's simulated hours and the fit's figures (mean per-step rmse after the
polynomial, mean per-step χ²/dof, |drift| after), so whether the order changes the
fit is measured, not argued. About 15–30 s per order on an idle machine.

Usage: .venv/bin/python benchmarks/bench_soak_order.py [--positions table1] [--random 100]
       .venv/bin/python benchmarks/bench_soak_order.py --demo [--orders table,travel,balanced]
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.position_order import (
    DEFAULT_ACCEL_DEG_PER_S2,
    DEFAULT_SLEW_DEG_PER_S,
    order_positions,
    travel_s,
)
from drivers.geometry import angles_for_references
from service.engine.spec import schedule_refs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--positions", default="table1")
    ap.add_argument("--random", type=int, default=100, help="random orders (seeds 0…N−1)")
    ap.add_argument("--slew-deg-per-s", type=float, default=DEFAULT_SLEW_DEG_PER_S)
    ap.add_argument("--accel-deg-per-s2", type=float, default=DEFAULT_ACCEL_DEG_PER_S2)
    ap.add_argument("--demo", action="store_true", help="the engine's demo in each order")
    ap.add_argument("--orders", default="table,travel,balanced", help="with --demo")
    args = ap.parse_args()
    if args.demo:
        return demo_orders(args.orders.split(","))
    a = angles_for_references(schedule_refs(args.positions))
    home = tuple(0.0 for _ in range(a.shape[1]))
    kw = {"slew_deg_per_s": args.slew_deg_per_s, "accel_deg_per_s2": args.accel_deg_per_s2}
    table = travel_s(a, range(len(a)), home, **kw)
    best = travel_s(a, order_positions(a, start_deg=home, **kw), home, **kw)
    rand = [travel_s(a, order_positions(a, method="random", seed=s), home, **kw)
            for s in range(args.random)]
    print(f"{args.positions}: {len(a)} positions, table {args.slew_deg_per_s:g} °/s, "
          f"{args.accel_deg_per_s2:g} °/s²; move time per step sweep, from home")
    print(f"  schedule order   {table:7.1f} s")
    print(f"  least travel     {best:7.1f} s  ({best / table:.2f}×)")
    print(f"  random (N={args.random})  {np.mean(rand):7.1f} s mean "
          f"({np.mean(rand) / table:.2f}×, min {min(rand):.1f} s)")
    return 0


def demo_orders(orders: list[str]) -> int:
    """``soakcal demo --position-order X`` per order: simulated h and the fit's figures."""
    print(f"{'order':>9} {'wall s':>7} {'simulated h':>11} {'rmse after µg':>13} "
          f"{'chi2/dof':>8} {'|drift| after µg/K':>18}")
    for order in orders:
        with tempfile.TemporaryDirectory() as out:
            t0 = time.monotonic()
            proc = subprocess.run(
                [sys.executable, "-m", "service.cli", "demo", "--position-order", order,
                 "--out", out], capture_output=True, text=True, check=False)
            wall_s = time.monotonic() - t0
            if proc.returncode != 0:
                raise SystemExit(f"demo --position-order {order} failed:\n{proc.stdout}")
            report = json.loads((Path(out) / "report.json").read_text())
        sim = re.search(r"simulated ([0-9.]+) h", proc.stdout)
        steps = report["steps"]
        rmse_ug = 1e3 * float(np.mean([s["rmse_polynomial_mg"] for s in steps]))
        chi2 = float(np.mean([s["chi2_red"] for s in steps]))
        drift = max(abs(v) for v in report["drift"]["after"]["slope_ug_per_k"])
        print(f"{order:>9} {wall_s:7.1f} {sim.group(1) if sim else '?':>11} {rmse_ug:13.2f} "
              f"{chi2:8.3f} {drift:18.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
