"""Simulated campaign duration: our stability decision vs the seed's fixed 1-hour soak.

Runs the full −40…60 °C Table-1 campaign through the real stacks (simulated
rig over loopback Modbus/serial, engine, SQLite, calibration core) in virtual
time, once per soak policy, and compares

* simulated campaign duration and total soak time, and
* held-out accuracy: the fitted model applied to noise-free readings of the
  simulator's *true* sensor at 60 directions (Fibonacci sphere, not the
  Table 1 set) and die temperatures between the setpoints; rms vector
  error in µg.

Usage: .venv/bin/python benchmarks/bench_soak_time.py [--fast]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from calibration.schedules import sphere
from drivers.clock import VirtualClock
from service.db.session import make_session_factory, upgrade_database
from service.demo import SETPOINTS_C, _create_campaign, demo_spec
from service.engine import store
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner
from simulators.truth import SensorTruth

SEED = 1
VARIANTS: dict[str, dict[str, Any]] = {
    "fixed 60 min (seed)": {"stability": "fixed"},
    "predictive, die tol 0.1 °C": {"stability": "predictive", "die_tol_c": 0.1},
    "predictive, die tol 0.5 °C": {"stability": "predictive", "die_tol_c": 0.5},
    "predictive, die tol 1.0 °C": {"stability": "predictive", "die_tol_c": 1.0},
}


async def run_campaign(spec: dict[str, Any], db_dir: Path) -> tuple[Any, float, list[dict]]:
    url = f"sqlite:///{db_dir / 'bench.db'}"
    upgrade_database(url)
    sf = make_session_factory(url)
    store.fast_sqlite_commits(sf)
    cid = _create_campaign(sf, spec)
    clock = VirtualClock(idle_wall_s=0.0003)
    async with open_rig({"name": "sim", "chamber": {"driver": "sim"}}, clock, seed=SEED) as dev:
        runner = CampaignRunner(sf, cid, dev, clock)
        state = await runner.run()
    camp = store.load_campaign(sf, cid)
    if state != "completed":
        raise RuntimeError(f"campaign {state}: {camp.error}")
    return runner.fit_result, clock.now(), camp.steps_log


def heldout_rmse_ug(model: Any, truth: SensorTruth, temps_die_c: np.ndarray) -> float:
    refs = sphere(60)
    errs = []
    for die_c in temps_die_c:
        raw = truth.ideal_raw_g(refs, die_c)
        out = model.compensate(raw, die_c + truth.temp_offset_c, extrapolate=True)
        errs.append(np.linalg.norm(out - refs, axis=1))
    return float(np.sqrt(np.mean(np.square(np.concatenate(errs))))) * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fast", action="store_true", help="3 steps instead of 11")
    args = ap.parse_args()
    truth = SensorTruth.adxl355_typical(SEED)
    sp = demo_spec(args.fast)["setpoints_c"] if args.fast else SETPOINTS_C
    temps = np.arange(sp[0] + 5.0, sp[-1], 10.0)
    rows = []
    for name, extra in VARIANTS.items():
        w0 = time.monotonic()
        with tempfile.TemporaryDirectory() as d:
            fit, sim_s, log = asyncio.run(run_campaign({**demo_spec(args.fast), **extra}, Path(d)))
        soak_s = sum(e["soak_s"] for e in log)
        rows.append((name, sim_s, soak_s, heldout_rmse_ug(fit.model, truth, temps),
                     time.monotonic() - w0))
        print(f"{name:<28} campaign {sim_s / 3600:6.2f} h  soak {soak_s / 3600:6.2f} h  "
              f"held-out {rows[-1][3]:7.1f} µg  [wall {rows[-1][4]:.0f} s]", flush=True)
    base = rows[0]
    print("\nrelative to the fixed soak:")
    for name, sim_s, soak_s, rmse, _ in rows[1:]:
        print(f"  {name:<28} campaign ×{sim_s / base[1]:.2f}  soak ×{soak_s / base[2]:.2f}  "
              f"held-out error ×{rmse / base[3]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
