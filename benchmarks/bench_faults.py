"""Campaign pace under Modbus faults: the twin over the real wire at 100×, 0 % and 20 % faults.

    .venv/bin/python benchmarks/bench_faults.py [--speed 100] [--p-fault 0.2]
        [--read-attempts 3 --write-attempts 3] [--wall-cap-s 600] [--chamber-map eurotherm3216]

One short campaign (three steps × 24 positions, 72 positions) runs through the
real engine (CampaignRunner, its guard and suspenders), the real drivers and the
twin's Modbus chamber and table servers on loopback TCP, with a ScaledClock at
``--speed`` (simulated seconds per wall second), once without faults (the control)
and once with ``--p-fault`` of the chamber's and the table's Modbus requests failing,
split as ``bench_faulty_twin`` does: 60 % DEVICE BUSY, 30 % connection dropped,
10 % reply swallowed (the client waits its 1 s wall timeout). The sensor bridge is
fault-free: this measures the Modbus link.

Per run it prints: completed or not, positions stored of 72, wall time, positions
per wall minute, the link's requests and retries, the engine guard's retries,
suspensions (count and wall seconds each), and the campaign time.

``--read-attempts 1 --write-attempts 1`` is the link without per-request retries
(every fault goes to the engine's guard, which retries the whole call: a status
read of several requests), which is how the link ran before per-request retries.

A faulty run is judged against what its faults explain: the extra wall time of a
fault is its retry (milliseconds), a reconnect (pymodbus idles 0.1 s wall), or a
1 s reply timeout; ``explained_s`` adds those up from the link's counts, and the
run's wall time beyond the control's should be of that size, not of 30-s suspensions.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from sqlalchemy import select  # noqa: E402

from benchmarks.bench_faulty_twin import twenty_percent  # noqa: E402
from drivers.clock import ScaledClock  # noqa: E402
from drivers.modbus_link import RetryPolicy  # noqa: E402
from service.db.models import Campaign, Measurement, Rig  # noqa: E402
from service.db.session import make_session_factory, upgrade_database  # noqa: E402
from service.engine.rigs import open_rig  # noqa: E402
from service.engine.runner import CampaignRunner  # noqa: E402
from service.engine.store import fast_sqlite_commits  # noqa: E402
from simulators.faults import SimFaults  # noqa: E402
from simulators.rig import RigFaults, start_sim_rig  # noqa: E402

SPEC = {"setpoints_c": [15.0, 30.0, 45.0], "soak_min": 20.0, "positions": "table1",
        "samples_per_position": 50, "ramp_c_per_min": 2.0}
N_POSITIONS = 3 * 24


def faults_at(p: float) -> SimFaults:
    """``p`` of requests failing, split as ``bench_faulty_twin.twenty_percent`` splits 20 %."""
    ref = twenty_percent()
    k = p / 0.2
    return SimFaults(p_exception=ref.p_exception * k, p_drop=ref.p_drop * k,
                     p_no_reply=ref.p_no_reply * k)


async def run_campaign(sf: Any, *, p_fault: float, speed: float, policy: RetryPolicy,
                       wall_cap_s: float, chamber_map: str, seed: int) -> dict[str, Any]:
    with sf() as s:
        if s.get(Rig, 1) is None:
            s.add(Rig(name="lab", chamber={"driver": "modbus"}, turntable={}, sensors=[]))
            s.flush()
        c = Campaign(rig="lab", sensor="SN-F", spec=dict(SPEC), state="queued", progress={},
                     steps_log=[])
        s.add(c)
        s.commit()
        cid = c.id
    clock = ScaledClock(speed)
    faults = (RigFaults(chamber=faults_at(p_fault), table=faults_at(p_fault))
              if p_fault > 0 else None)
    suspensions: list[dict[str, Any]] = []
    async with start_sim_rig(clock, seed=seed, faults=faults, chamber_map=chamber_map) as sim:
        cfg = {"name": "lab",
               "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": sim.chamber_map},
               "turntable": {"url": sim.table_url},
               "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}
        async with open_rig(cfg, clock) as dev:
            links = (dev.chamber.link, dev.turntable.link)
            for link in links:
                link.policy = policy
            runner = CampaignRunner(sf, cid, dev, clock)
            suspend, resume = runner._suspend, runner._unsuspend

            def on_suspend(reason: str) -> None:  # the guard's hook, timed in wall seconds
                suspensions.append({"reason": reason, "t0": time.perf_counter(), "wall_s": None})
                suspend(reason)

            def on_resume() -> None:
                if suspensions and suspensions[-1]["wall_s"] is None:
                    suspensions[-1]["wall_s"] = time.perf_counter() - suspensions[-1]["t0"]
                resume()

            runner._suspend, runner._unsuspend = on_suspend, on_resume  # type: ignore[method-assign]
            t0 = time.perf_counter()
            task = asyncio.create_task(runner.run())
            done, _ = await asyncio.wait({task}, timeout=wall_cap_s)
            if task in done:
                state = task.result()
            else:
                task.cancel()
                state = "cut at the wall cap"
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task  # only what it stored counts
            wall_s = time.perf_counter() - t0
            stats = {k: sum(link.stats[k] for link in links)
                     for k in ("requests", "retries", "reconnects")}
            guard = getattr(runner, "guard", None)
            stats["guard_retries"] = guard.faults_retried if guard is not None else 0
    for s_ in suspensions:
        if s_["wall_s"] is None:
            s_["wall_s"] = time.perf_counter() - s_["t0"]
    with sf() as s:
        n = len(s.execute(select(Measurement.id).where(Measurement.campaign_id == cid)).all())
    return {"state": state, "positions": n, "wall_s": wall_s, "stats": stats,
            "suspensions": suspensions, "campaign_h": clock.now() / 3600.0}


def explained_s(r: dict[str, Any], p_fault: float, timeout_s: float) -> float:
    """Wall seconds the faults themselves cost: a timeout per swallowed reply, 0.1 s per
    reconnect (the requests' expected share of swallowed replies: 10 % of faults)."""
    faults = r["stats"]["requests"] * p_fault
    return faults * 0.1 * timeout_s + r["stats"]["reconnects"] * 0.1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=100.0, help="ScaledClock factor")
    ap.add_argument("--p-fault", type=float, default=0.2, help="faulty share of Modbus requests")
    ap.add_argument("--read-attempts", type=int, default=RetryPolicy().read_attempts)
    ap.add_argument("--write-attempts", type=int, default=RetryPolicy().write_attempts)
    ap.add_argument("--wall-cap-s", type=float, default=600.0,
                    help="stop a run after this many wall seconds and count what it stored")
    ap.add_argument("--chamber-map", default="eurotherm3216")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--no-control", action="store_true", help="skip the fault-free run")
    a = ap.parse_args(argv)
    policy = RetryPolicy(read_attempts=a.read_attempts, write_attempts=a.write_attempts)
    runs = ([] if a.no_control else [0.0]) + [a.p_fault]
    print(f"campaign: {SPEC['setpoints_c']} °C × 24 positions, {SPEC['samples_per_position']} "
          f"samples, at {a.speed:g}×, chamber map {a.chamber_map}; link tries: read "
          f"{a.read_attempts}, idempotent write {a.write_attempts}; reply timeout "
          f"{policy.timeout_s:g} s wall")
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{tmp}/bench.db"
        upgrade_database(url)
        sf = make_session_factory(url)
        fast_sqlite_commits(sf)
        control_wall_s = None
        for p in runs:
            r = asyncio.run(run_campaign(sf, p_fault=p, speed=a.speed, policy=policy,
                                         wall_cap_s=a.wall_cap_s, chamber_map=a.chamber_map,
                                         seed=a.seed))
            st = r["stats"]
            susp = r["suspensions"]
            walls = ", ".join(f"{x['wall_s']:.1f}" for x in susp)
            per_min = r["positions"] / (r["wall_s"] / 60.0)
            line = (f"{p:>4.0%} faults: {r['state']}, {r['positions']}/{N_POSITIONS} positions "
                    f"in {r['wall_s']:.1f} s wall = {per_min:.1f} positions/wall min; "
                    f"{r['campaign_h']:.2f} h campaign; Modbus requests {st['requests']}, "
                    f"link retries {st['retries']}, reconnects {st['reconnects']}, "
                    f"guard retries {st['guard_retries']}; suspensions {len(susp)}")
            print(line + (f" ({walls} s wall each)" if susp else ""))
            if p == 0.0:
                control_wall_s = r["wall_s"]
            elif control_wall_s is not None:
                extra = r["wall_s"] - control_wall_s
                print(f"      extra wall time over the control {extra:.1f} s; the faults explain "
                      f"≈ {explained_s(r, p, policy.timeout_s):.1f} s (timeouts and reconnects)")
            ok = ok and r["state"] == "completed"
        sf.kw["bind"].dispose()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
