"""A campaign through the twin with 20 % of Modbus requests failing and the chamber alarm twice.

    .venv/bin/python benchmarks/bench_faulty_twin.py [--steps-c -40,-10,20,50] [--samples 100]

The engine (CampaignRunner: plan, guard, suspenders, commit-on-save) runs the
same campaign twice through the wire-level twin (Modbus chamber and table
servers on loopback, serial sensor bridge, VirtualClock) on one simulated
ADXL355 (``SensorTruth.adxl355_typical(seed)``):

* fault-free;
* with 20 % of the chamber's and the table's Modbus requests failing
  (DEVICE BUSY 12 %, connection dropped 6 %, reply swallowed 2 %) and the
  chamber's door "opened" twice mid-sweep (air +12 °C: the controller's
  deviation alarm).

Each run is fitted by the real calibration core; the held-out accuracy is the
RMS vector error (µg) of each model on one verification run (fresh noise,
die at −35, −5, 25, 55 °C, 60 random orientations each). Prints whether both
completed, whether every (step, position) was stored exactly once, the
faults absorbed, the holds, both accuracies and their ratio, and wall times.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from sqlalchemy import select  # noqa: E402

from calibration import sfem  # noqa: E402
from drivers.clock import VirtualClock  # noqa: E402
from drivers.modbus_link import RetryPolicy  # noqa: E402
from service.db.models import Campaign, Measurement, Rig  # noqa: E402
from service.db.session import make_session_factory, upgrade_database  # noqa: E402
from service.engine.rigs import open_rig  # noqa: E402
from service.engine.runner import CampaignRunner  # noqa: E402
from service.engine.store import fast_sqlite_commits  # noqa: E402
from simulators.campaign_sim import simulate_static_run  # noqa: E402
from simulators.faults import SimFaults  # noqa: E402
from simulators.rig import RigFaults, start_sim_rig  # noqa: E402
from simulators.truth import SensorTruth  # noqa: E402

HELDOUT_C = (-35.0, -5.0, 25.0, 55.0)


def twenty_percent() -> SimFaults:
    return SimFaults(p_exception=0.12, p_drop=0.06, p_no_reply=0.02)


async def run_campaign(sf: Any, spec: dict[str, Any], truth: SensorTruth, *, faulty: bool,
                       seed: int) -> dict[str, Any]:
    with sf() as s:
        if s.get(Rig, 1) is None:
            s.add(Rig(name="lab", chamber={"driver": "modbus"}, turntable={}, sensors=[]))
            s.flush()
        c = Campaign(rig="lab", sensor="SN-B", spec=spec, state="queued", progress={},
                     steps_log=[])
        s.add(c)
        s.commit()
        cid = c.id
    clock = VirtualClock(idle_wall_s=0.0003)
    faults = RigFaults(chamber=twenty_percent(), table=twenty_percent()) if faulty else None
    t0 = time.perf_counter()
    async with start_sim_rig(clock, seed=seed, truth=truth, faults=faults) as sim:
        cfg = {"name": "lab",
               "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": sim.chamber_map},
               "turntable": {"url": sim.table_url},
               # the twin reached by URL reports its own serial: bind any (as the sim rig does)
               "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}
        async with open_rig(cfg, clock) as dev:
            for link in (dev.chamber.link, dev.turntable.link):  # loopback: short wall timeout
                link.policy = RetryPolicy(timeout_s=0.25)
            runner = CampaignRunner(sf, cid, dev, clock)
            task = asyncio.create_task(runner.run())
            if faulty:
                n_total = len(spec["setpoints_c"]) * 24
                for frac in (0.3, 0.7):  # the door opens twice, mid-sweep
                    while count(sf, cid) < int(frac * n_total) and not task.done():
                        await asyncio.sleep(0.01)
                    sim.chamber.advance_to()
                    sim.chamber.air_c += 12.0
            state = await task
            stats = {"requests": dev.chamber.link.stats["requests"]
                     + dev.turntable.link.stats["requests"],
                     "reconnects": dev.chamber.link.stats["reconnects"]
                     + dev.turntable.link.stats["reconnects"],
                     "engine_retries": runner.guard.faults_retried,
                     "guard_suspensions": runner.guard.suspensions}
    with sf() as s:
        keys = Counter((int(a), int(b)) for a, b in s.execute(
            select(Measurement.step, Measurement.position)
            .where(Measurement.campaign_id == cid)).all())
    return {"state": state, "keys": keys, "fit": runner.fit_result, "stats": stats,
            "holds": [h["suspender"] for h in runner.suspension_log],
            "wall_s": time.perf_counter() - t0, "campaign_h": clock.now() / 3600.0}


def count(sf: Any, cid: int) -> int:
    with sf() as s:
        return len(s.execute(select(Measurement.id).where(Measurement.campaign_id == cid)).all())


def heldout_rmse_ug(fit: Any, truth: SensorTruth, seed: int) -> float:
    rng = np.random.default_rng(seed + 20_000)
    refs = np.vstack([_unit(rng.normal(size=(60, 3))) for _ in HELDOUT_C])
    die = np.repeat(HELDOUT_C, 60)
    run = simulate_static_run(truth, refs, die, seed=seed + 30_000)
    cal = fit.model.compensate(run.recording.raw_g, run.recording.temperature_c(),
                               extrapolate=True)
    return float(np.sqrt(np.mean(np.sum((cal - refs) ** 2, axis=1)) / 3) * 1e6)


def oracle_rmse_ug(truth: SensorTruth, seed: int) -> float:
    rng = np.random.default_rng(seed + 20_000)
    refs = np.vstack([_unit(rng.normal(size=(60, 3))) for _ in HELDOUT_C])
    die = np.repeat(HELDOUT_C, 60)
    run = simulate_static_run(truth, refs, die, seed=seed + 30_000)
    oracle = sfem.forward(truth.params_vector_at(die), run.recording.raw_g)
    return float(np.sqrt(np.mean(np.sum((oracle - refs) ** 2, axis=1)) / 3) * 1e6)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps-c", default="-40,-10,20,50", help="setpoints, °C")
    ap.add_argument("--samples", type=int, default=100, help="samples per position")
    ap.add_argument("--soak-min", type=float, default=30.0, help="nominal soak per step, min")
    ap.add_argument("--seed", type=int, default=2)
    a = ap.parse_args(argv)
    spec = {"setpoints_c": [float(v) for v in a.steps_c.split(",")], "soak_min": a.soak_min,
            "positions": "table1", "samples_per_position": a.samples, "ramp_c_per_min": 2.0}
    truth = SensorTruth.adxl355_typical(a.seed)
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{tmp}/bench.db"
        upgrade_database(url)
        sf = make_session_factory(url)
        fast_sqlite_commits(sf)
        clean = asyncio.run(run_campaign(sf, spec, truth, faulty=False, seed=a.seed))
        faulty = asyncio.run(run_campaign(sf, spec, truth, faulty=True, seed=a.seed))
        sf.kw["bind"].dispose()
    expected = {(s, p) for s in range(len(spec["setpoints_c"])) for p in range(24)}
    oracle = oracle_rmse_ug(truth, a.seed)
    print(f"campaign: {spec['setpoints_c']} °C × 24 positions × {a.samples} samples, "
          f"predictive soak (nominal {a.soak_min:g} min)")
    for name, r in (("fault-free", clean), ("20 % faults + 2 alarms", faulty)):
        once = set(r["keys"]) == expected and max(r["keys"].values()) == 1
        acc = heldout_rmse_ug(r["fit"], truth, a.seed) if r["fit"] is not None else float("nan")
        r["acc"] = acc
        print(f"{name:>24}: {r['state']}, every (step, position) exactly once: {once}, "
              f"held-out RMS {acc:.1f} µg (oracle {oracle:.1f} µg), "
              f"{r['campaign_h']:.1f} h campaign in {r['wall_s']:.1f} s wall; "
              f"Modbus requests {r['stats']['requests']}, engine retries "
              f"{r['stats']['engine_retries']}, reconnects {r['stats']['reconnects']}, "
              f"holds {r['holds']}")
    print(f"held-out accuracy ratio faulty / fault-free: {faulty['acc'] / clean['acc']:.3f}")
    ok = (clean["state"] == faulty["state"] == "completed"
          and set(faulty["keys"]) == expected and max(faulty["keys"].values()) == 1
          and faulty["holds"].count("chamber_alarm") == 2)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
