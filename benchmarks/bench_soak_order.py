"""Table move time of one step's sweep: Table 1 order vs least travel vs seeded random orders.

Move times by the trapezoidal profile of service.engine.soak_order (the simulated
table's 20 °/s, 40 °/s² unless given), from the home pose (all axes 0°), for the
positions of a schedule mapped to table angles by drivers.geometry. Pure
arithmetic, < 1 s.

Usage: .venv/bin/python benchmarks/bench_soak_order.py [--positions table1] [--random 100]
"""

from __future__ import annotations

import argparse

import numpy as np

from service.engine.soak_order import (
    DEFAULT_ACCEL_DEG_PER_S2,
    DEFAULT_SLEW_DEG_PER_S,
    angles_of,
    order_positions,
    travel_s,
)
from service.engine.spec import schedule_refs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--positions", default="table1")
    ap.add_argument("--random", type=int, default=100, help="random orders (seeds 0…N−1)")
    ap.add_argument("--slew-deg-per-s", type=float, default=DEFAULT_SLEW_DEG_PER_S)
    ap.add_argument("--accel-deg-per-s2", type=float, default=DEFAULT_ACCEL_DEG_PER_S2)
    args = ap.parse_args()
    a = angles_of(schedule_refs(args.positions))
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


if __name__ == "__main__":
    raise SystemExit(main())
