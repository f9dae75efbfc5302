"""Digital-twin throughput: a whole −40…60 °C soak campaign through the drivers on loopback.

11 temperature steps × 24 orientations × 200 samples, ~1 h soak per step in
simulated time, on the VirtualClock. Chamber, table and sensor bridge run as
real servers on 127.0.0.1; the campaign talks to them only through the
drivers. Prints the wall time (target < 10 s).

    .venv/bin/python benchmarks/bench_twin.py
"""

from __future__ import annotations

import argparse
import asyncio
import math
import time

import numpy as np

from drivers.clock import VirtualClock
from drivers.geometry import angles_for_reference
from simulators.rig import connect_rig, start_sim_rig

STEPS_C = [-40.0 + 10.0 * k for k in range(11)]


def fibonacci_directions(n: int) -> list[np.ndarray]:
    """``n`` roughly uniform unit vectors: a stand-in for a real position schedule."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for i in range(n):
        z = 1.0 - 2.0 * (i + 0.5) / n
        r = math.sqrt(1.0 - z * z)
        out.append(np.array([r * math.cos(golden * i), r * math.sin(golden * i), z]))
    return out


async def run_campaign(n_positions: int = 24, n_samples: int = 200, soak_s: float = 3600.0,
                       seed: int = 1, in_memory: bool = False) -> dict[str, float]:
    clock = VirtualClock()
    rows = 0
    worst_norm_err = 0.0
    async with start_sim_rig(clock, seed=seed, modbus_in_memory=in_memory) as rig:
        chamber, table, sensor = await connect_rig(rig, clock)
        await sensor.configure(2.0, 62.5)
        await chamber.set_ramp_rate(2.0)
        await chamber.run()
        schedule = [angles_for_reference(v) for v in fibonacci_directions(n_positions)]
        for sp in STEPS_C:
            await chamber.set_setpoint(sp)
            while abs((await chamber.read_status()).process_c - sp) > 0.3:
                await clock.sleep(60.0)
            t_end = clock.now() + soak_s
            while clock.now() < t_end:  # soak, watching the chamber as the engine would
                await clock.sleep(300.0)
                await chamber.read_status()
            for angles in schedule:
                await table.move_to(angles)
                while not (await table.read_status()).in_position:
                    await clock.sleep(2.0)  # engine-style poll interval
                acq = await sensor.acquire(n_samples)
                rows += 1
                worst_norm_err = max(worst_norm_err, abs(float(np.linalg.norm(acq.mean_g)) - 1))
        await chamber.stop()
        await sensor.close()
        requests = chamber.link.stats["requests"] + table.link.stats["requests"]
    return {"rows": rows, "modbus_requests": requests, "sim_hours": clock.now() / 3600.0,
            "worst_norm_err_g": worst_norm_err}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--positions", type=int, default=24)
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--soak-s", type=float, default=3600.0)
    p.add_argument("--in-memory", action="store_true",
                   help="chamber and table over pymodbus' null modem instead of loopback TCP")
    args = p.parse_args()
    t0 = time.perf_counter()  # wall time of the benchmark itself, not simulation time
    res = asyncio.run(run_campaign(args.positions, args.samples, args.soak_s,
                                   in_memory=args.in_memory))
    wall = time.perf_counter() - t0
    print(f"bench_twin: {res['rows']} rows ({len(STEPS_C)} steps × {args.positions} positions × "
          f"{args.samples} samples), {res['sim_hours']:.1f} h simulated in {wall:.2f} s wall "
          f"({res['sim_hours'] * 3600 / wall:.0f}× real time); "
          f"{res['modbus_requests']} Modbus requests over "
          f"{'null modem' if args.in_memory else 'loopback TCP'}; "
          f"max | |a|−1 g | = {res['worst_norm_err_g'] * 1e3:.1f} mg")


if __name__ == "__main__":
    main()
