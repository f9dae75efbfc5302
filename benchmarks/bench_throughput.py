"""Throughput: N sensors in ONE simulated campaign vs the seed's fixed hour (issue 12).

One campaign mounts N simulated sensors (``open_rig(..., serials=[...])``) in one chamber
on one table and runs the full −40…60 °C Table-1 protocol through the real engine,
SQLite and calibration core in virtual time, once per soak policy:

* ``fixed 60 min (seed)``: the seed's fixed one-hour soak with the same N sensors, the
  reference: each sensor's own fixed-hour held-out error;
* ``measured k, corrected``: the engine's ``rate_gain: "measured"`` soak (docs/engine.md);
* ``predictive (default)``: the default predictive soak.

Every policy mounts the same parts: sensor i is ``bench_soak_time.make_truth(i, …)``,
injected per serial (``sim_options={"truths": …}``) with its common-random-number
streams (position captures keyed by (sensor, k), see ``BenchTruth``) and the optional
``temperature_rate`` effect, whose die rate comes from the rig's one shared chamber.
Held-out error per sensor: ``bench_soak_time.heldout_errors_g`` (60 Fibonacci-sphere
directions × die temperatures between the setpoints, noise-free truth).

Throughput is sensors per chamber-hour against the seed's protocol, 1 sensor per
``SEED_HOURS_PER_SENSOR`` (13.9 h, issue 12). Required: 8 sensors in ≤ 0.7 × 13.9 h with
every sensor's held-out error ≤ 1.05 × its fixed-hour figure; aim: 16 in ≤ 0.5 ×.

``--rate-ug-per-c-per-min 0,100`` cycles the rate gains over the sensors (a mixed
campaign: odd sensors 0, even 100). Each campaign runs in its own process (peak RSS is
that process's ``ru_maxrss``).

``--dump DIR`` writes each campaign's stored rows, k̂ and every position capture's noise-free
mean per sensor to DIR (JSON), for ``bench_heldout_steps.py`` (per step, per held-out
temperature, and the soak-only error and expected per-sensor ratio).

Usage: .venv/bin/python benchmarks/bench_throughput.py [--sensors 8] [--fast] [--jobs N]
                                                       [--rate-ug-per-c-per-min K[,K…]]
                                                       [--variants 1,2] [--draws N]
                                                       [--dump DIR]
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import logging
import math
import resource
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.bench_soak_time import (  # noqa: E402  (the path above: run as a script)
    EQUAL_ACCURACY,
    VARIANTS,
    catching_chamber,
    heldout_errors_g,
    make_truth,
)
from drivers.clock import VirtualClock  # noqa: E402
from service.db.session import make_session_factory, upgrade_database  # noqa: E402
from service.demo import SETPOINTS_C, _create_campaign, demo_spec  # noqa: E402
from service.engine import store  # noqa: E402
from service.engine.calibrate import CalibrationRow, calibrate_columns  # noqa: E402
from service.engine.rigs import open_rig  # noqa: E402
from service.engine.runner import CampaignRunner  # noqa: E402

SEED_HOURS_PER_SENSOR = 13.9  # the seed's protocol: one sensor per 13.9 chamber-hours
REQUIRED_TIME_RATIO = 0.7  # 8 sensors in ≤ 0.7 × the seed's fixed-hour campaign
RIG_SEED = 1  # the chamber's, table's and die probes' streams: the same in every policy
POLICIES = ["fixed 60 min (seed)", "measured k, corrected", "predictive (default)",
            "fixed 60 min, next draw", "measured k, balanced order"]
# The fixed hour again with the next noise draw (crn offset + 1): how far a sensor's held-out
# error moves between two independent noise draws of the same part and the same soak, the
# metric's own spread against which a per-sensor ratio of one draw is judged.
NEXT_DRAW = "fixed 60 min, next draw"


def serials_for(n_sensors: int) -> list[str]:
    """Sensor i (1…N) of the fixture is the bench's part ``make_truth(i)``."""
    return [f"SN-T{i:04d}" for i in range(1, n_sensors + 1)]


def rate_of(index: int, rates: list[float]) -> float:
    """The temperature_rate gain (µg per °C/min) of the index-th sensor (0-based): cycled."""
    return rates[index % len(rates)]


def make_truths(n_sensors: int, rates: list[float], probe_n: int,
                noise_free: bool = False, crn_offset: int = 0) -> dict[str, Any]:
    """Every serial's BenchTruth, reporting its serial (the twin's identity check).

    ``crn_offset`` > 0: the same parts with other noise streams (another draw per part).
    """
    out = {}
    for i, serial in enumerate(serials_for(n_sensors)):
        truth = make_truth(i + 1, noise_free, rate_of(i, rates), probe_n)
        out[serial] = dataclasses.replace(truth, serial=serial,
                                          crn_seed=truth.crn_seed + 1000 * crn_offset)
    return out


async def run_several(spec: dict[str, Any], db_dir: Path, truths: dict[str, Any],
                      rig_seed: int = RIG_SEED) -> tuple[dict[str, Any], float, list[dict], dict]:
    """One campaign of every serial in ``truths``; each sensor's fit, simulated s, log."""
    url = f"sqlite:///{db_dir / 'bench.db'}"
    upgrade_database(url)
    sf = make_session_factory(url)
    store.fast_sqlite_commits(sf)
    serials = list(truths)
    cid = _create_campaign(sf, {**spec, "sensors": serials})
    clock = VirtualClock(idle_wall_s=0.0003)
    fits: dict[str, Any] = {}
    k_hats: dict[str, tuple[list[float], list[float]]] = {}

    def calibrate(cols: Any, provenance: dict[str, Any]) -> CalibrationRow:
        values = calibrate_columns(cols, provenance)
        fits[str(provenance["sensor"])] = SimpleNamespace(model=values.fit.model)
        est = provenance.get("rate_gain_estimate")  # rate_gain measured: the campaign's k̂
        if est:
            k_hats[str(provenance["sensor"])] = (est["gain_ug_per_c_per_min"],
                                                 est["sd_ug_per_c_per_min"])
        return values

    with catching_chamber(truths.values()):
        async with open_rig({"name": "sim", "chamber": {"driver": "sim"}}, clock,
                            seed=rig_seed, serials=serials,
                            sim_options={"truths": truths, "modbus_in_memory": True}) as dev:
            runner = CampaignRunner(sf, cid, dev, clock, calibrate=calibrate)
            state = await runner.run()
    camp = store.load_campaign(sf, cid)
    if state != "completed":
        raise RuntimeError(f"campaign {state}: {camp.error}")
    cols = store.measurement_columns(sf, cid, serials[0])
    log = [{**e, "rows_t_s": [t for t, st in zip(cols["t_s"], cols["step"], strict=True)
                              if int(st) == e["step"]]} for e in camp.steps_log]
    for serial, k in k_hats.items():
        if serial in fits:
            fits[serial].k_hat = k  # the estimate the fit used, read by one_campaign
    for serial in fits:
        fits[serial].columns = store.measurement_columns(sf, cid, serial)  # for --dump
    return fits, clock.now(), log, dict(camp.sensors_dropped or {})


def one_campaign(args: tuple[str, int, bool, list[float], bool, int, str]) -> dict[str, Any]:
    """One N-sensor campaign under one policy; runs in its own worker process.

    ``dump`` (a folder, or ""): each sensor's stored rows and the campaign's k̂ are written
    there as JSON (``dump_name``), for the per-step analysis of ``bench_heldout_steps.py``.
    """
    name, n_sensors, fast, rates, noise_free, crn_offset, dump = args
    logging.getLogger("soakcal").setLevel(logging.WARNING)  # no per-soak event lines
    if name == NEXT_DRAW:
        crn_offset += 1
    variant = VARIANTS[POLICIES[0] if name == NEXT_DRAW else name]
    probe_n = int(variant.get("soak_probe_samples", 8))
    truths = make_truths(n_sensors, rates, probe_n, noise_free, crn_offset)
    sp = demo_spec(fast)["setpoints_c"] if fast else SETPOINTS_C
    temps = np.arange(sp[0] + 5.0, sp[-1], 10.0)
    w0 = time.monotonic()
    with tempfile.TemporaryDirectory() as d:
        fits, sim_s, log, dropped = asyncio.run(
            run_several({**demo_spec(fast), **variant}, Path(d), truths,
                        RIG_SEED + crn_offset))
    wall_s = time.monotonic() - w0
    per_sensor: dict[str, dict[str, float]] = {}
    for i, serial in enumerate(truths):
        if serial not in fits:
            continue
        err = heldout_errors_g(fits[serial].model, make_truth(i + 1, False, rate_of(i, rates)),
                               temps)
        per_sensor[serial] = {"sq_err": float(np.sum(err**2)), "n_err": int(err.size),
                              "rmse_ug": float(np.sqrt(np.mean(err**2))) * 1e6,
                              "k_hat": getattr(fits[serial], "k_hat", None)}
    if dump:
        Path(dump).mkdir(parents=True, exist_ok=True)
        (Path(dump) / dump_name(name, crn_offset)).write_text(json.dumps({
            "name": name, "draw": crn_offset, "rates": rates, "log": log,
            "sensors": {s: {"columns": fits[s].columns, "k_hat": getattr(fits[s], "k_hat", None),
                            "index": serials_for(n_sensors).index(s),
                            "noise_free": truths[s].noise_free_log} for s in fits}}))
    return {
        "name": name, "sim_s": sim_s, "soak_s": sum(e["soak_s"] for e in log),
        "max_soak": sum(bool(e.get("max_soak_reached")) for e in log),
        "per_sensor": per_sensor, "dropped": dropped, "wall_s": wall_s,
        # the k (µg per °C/min) each step's soak decision used, largest over the sensors
        "k_used": [e.get("rate_gain_ug_per_c_per_min") for e in log
                   if e.get("rate_gain_ug_per_c_per_min") is not None],
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "steps": step_breakdown(log, sim_s),
    }


def dump_name(policy: str, draw: int) -> str:
    """The --dump file of one campaign: the policy's name made a file name, and the draw."""
    return f"{''.join(c if c.isalnum() else '_' for c in policy)}-draw{draw}.json"


def step_breakdown(log: list[dict[str, Any]], sim_s: float) -> list[dict[str, float]]:
    """Where each step's time went (s): ramp (from the previous step's last capture, or the
    campaign start, to the soak's start: table parking, setpoint ramp, the air settling
    into the band, the poll that sees it), soak, and sweep (soak end to the step's last row:
    moves, settles, captures, saves). The rows' times are the first sensor's (all are
    read at once); what follows the last step's last row (the fit) is ``tail``."""
    out: list[dict[str, float]] = []
    prev_end_s = 0.0
    for e in sorted(log, key=lambda e: e["step"]):
        rows = e.get("rows_t_s") or [e["soak_end_t_s"]]
        out.append({"step": e["step"], "ramp_s": e["soak_start_t_s"] - prev_end_s,
                    "soak_s": e["soak_s"], "sweep_s": max(rows) - e["soak_end_t_s"],
                    "k": e.get("rate_gain_ug_per_c_per_min") or float("nan")})
        prev_end_s = max(rows)
    if out:
        out[-1]["tail_s"] = sim_s - prev_end_s
    return out


def pooled_rmse_ug(per_sensor: dict[str, dict[str, float]]) -> float:
    return 1e6 * float(np.sqrt(sum(r["sq_err"] for r in per_sensor.values())
                               / sum(r["n_err"] for r in per_sensor.values())))


def report(results: list[dict[str, Any]], n_sensors: int, rates: list[float]) -> None:
    """Per-sensor table, then per policy: time, throughput and the equal-accuracy verdict."""
    base = results[0]
    serials = serials_for(n_sensors)
    print("held-out rmse µg per sensor (ratio to its own fixed-hour figure)")
    print(f"{'sensor':<10} {'rate':>5} " + " ".join(f"{r['name'][:22]:>22}" for r in results))
    for i, serial in enumerate(serials):
        cells = []
        for r in results:
            got = r["per_sensor"].get(serial)
            ref = base["per_sensor"].get(serial)
            if got is None:
                cells.append(f"{'dropped':>22}")
            elif r is base or ref is None:
                cells.append(f"{got['rmse_ug']:>22.2f}")
            else:
                cells.append(f"{got['rmse_ug']:>12.2f} (×{got['rmse_ug'] / ref['rmse_ug']:.3f})")
        print(f"{serial:<10} {rate_of(i, rates):>5g} " + " ".join(cells))
    seed_h = SEED_HOURS_PER_SENSOR
    print(f"\n{'policy':<24} {'campaign':>9} {'soak':>7} {'×seed 1-sensor':>14} {'×fixed N':>9} "
          f"{'sensors/ch-h':>12} {'×seed':>6} {'pooled':>8} {'worst':>7}  {'wall s':>6} "
          f"{'RSS MiB':>7}  verdict")
    for r in results:
        hours = r["sim_s"] / 3600.0
        pooled = pooled_rmse_ug(r["per_sensor"]) / pooled_rmse_ug(base["per_sensor"])
        ratios = [r["per_sensor"][s]["rmse_ug"] / base["per_sensor"][s]["rmse_ug"]
                  for s in serials if s in r["per_sensor"] and s in base["per_sensor"]]
        worst = max(ratios) if ratios else float("nan")
        calibrated = len(r["per_sensor"])
        per_h = calibrated / hours
        ok_time = hours <= REQUIRED_TIME_RATIO * seed_h
        ok_acc = calibrated == n_sensors and worst <= EQUAL_ACCURACY
        verdict = ("reference" if r is base else
                   f"time {'met' if ok_time else 'NOT met'}, every sensor "
                   f"{'equal' if ok_acc else 'NOT equal'} (≤ ×{EQUAL_ACCURACY:.2f})")
        print(f"{r['name']:<24} {hours:7.2f} h {r['soak_s'] / 3600:5.2f} h {hours / seed_h:14.3f} "
              f"{r['sim_s'] / base['sim_s']:9.3f} {per_h:12.3f} {per_h * seed_h:6.1f} "
              f"{pooled:8.3f} {worst:7.3f}  {r['wall_s']:6.1f} {r['peak_rss_mib']:7.0f}  "
              f"{verdict}")
        if r["dropped"]:
            print(f"  dropped: {r['dropped']}")
    print("\nper step, minutes: ramp (incl. parking and the poll that sees the band) / soak / "
          "sweep (soak end → last capture)")
    for r in results:
        steps = r["steps"]
        cells = " ".join(f"{s['ramp_s'] / 60:.1f}/{s['soak_s'] / 60:.1f}/{s['sweep_s'] / 60:.1f}"
                         for s in steps)
        ramp = sum(s["ramp_s"] for s in steps) / 3600.0
        sweep = sum(s["sweep_s"] for s in steps) / 3600.0
        tail = (steps[-1].get("tail_s", 0.0) if steps else 0.0) / 3600.0
        print(f"{r['name']:<24} ramp {ramp:.2f} h, sweep {sweep:.2f} h, after the last row "
              f"{tail * 3600:.0f} s: {cells}")
    for r in results:
        k_hats = {s: v["k_hat"] for s, v in r["per_sensor"].items() if v.get("k_hat")}
        if k_hats:
            print(f"{r['name']}: the campaign's k̂ ± σ per sensor (x, y, z; µg per °C/min; true "
                  "gain × (1, −0.6, 0.4)): " + "; ".join(
                      f"{s[-4:]} " + " ".join(f"{k:+.1f}±{sd:.1f}" for k, sd in zip(*v,
                                                                                   strict=True))
                      for s, v in k_hats.items()))
    for r in results:
        if r["k_used"]:
            print(f"{r['name']}: k fed per step (µg per °C/min, largest over the sensors): "
                  + " ".join(f"{float(np.max(k)):.0f}" for k in r["k_used"]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", type=int, default=8, help="sensors in the one campaign (≥ 2)")
    ap.add_argument("--fast", action="store_true", help="3 steps instead of 11")
    ap.add_argument("--noise-free", action="store_true",
                    help="no accelerometer noise: held-out error = soak-induced part only")
    ap.add_argument("--crn-offset", type=int, default=0,
                    help="other noise streams for the same parts (positions and probes)")
    ap.add_argument("--draws", type=int, default=1,
                    help="repeat with this many noise draws (crn offsets N, N+1, …) and judge "
                         "each sensor over all of them")
    ap.add_argument("--jobs", type=int, default=1, help="campaigns run at once (processes)")
    ap.add_argument("--dump", default="",
                    help="write every campaign's rows and k̂ per sensor to this folder (JSON)")
    ap.add_argument("--rate-ug-per-c-per-min", default="0",
                    help="temperature_rate gain(s), µg per °C/min; a list cycles over sensors")
    ap.add_argument("--variants", default="",
                    help=f"numbers of the policies besides the fixed hour (1-{len(POLICIES) - 1}"
                         f", in the order {POLICIES[1:]})")
    args = ap.parse_args()
    if args.sensors < 2:
        ap.error("--sensors: a campaign of several sensors needs 2 or more")
    rates = [float(v) for v in str(args.rate_ug_per_c_per_min).split(",")]
    names = POLICIES
    if args.variants:
        names = [POLICIES[0]] + [POLICIES[int(i)] for i in args.variants.split(",")]
    by_draw = []
    for draw in range(args.crn_offset, args.crn_offset + max(1, args.draws)):
        w0 = time.monotonic()
        cases = [(name, args.sensors, args.fast, rates, args.noise_free, draw, args.dump)
                 for name in names]
        with ProcessPoolExecutor(max_workers=max(1, args.jobs), max_tasks_per_child=1) as pool:
            results = list(pool.map(one_campaign, cases))
        print(f"{args.sensors} sensors in one campaign, temperature_rate "
              f"{','.join(f'{v:g}' for v in rates)} µg per °C/min"
              f"{' (cycled over the sensors)' if len(rates) > 1 else ''}, "
              f"{'3 steps (--fast)' if args.fast else 'the seed protocol (11 steps)'}"
              f"{', noise-free accelerometer (verdicts do not apply)' if args.noise_free else ''}"
              f"{f', noise streams offset {draw}' if draw else ''}; "
              f"{time.monotonic() - w0:.0f} s wall, {args.jobs} job(s)\n")
        report(results, args.sensors, rates)
        print()
        by_draw.append(results)
    if len(by_draw) > 1:
        report_draws(by_draw, args.sensors)
    return 0


def report_draws(by_draw: list[list[dict[str, Any]]], n_sensors: int) -> None:
    """Each sensor judged over every draw: its held-out rms pooled over the draws against
    its fixed hour's pooled over the same draws; and how many single sensor-draws exceed
    ×1.05, and the campaign times."""
    serials = serials_for(n_sensors)
    names = [r["name"] for r in by_draw[0]]
    print(f"over {len(by_draw)} noise draws: each sensor's held-out rms pooled over the draws, "
          "ratio to its fixed hour's pooled over the same draws")
    print(f"{'sensor':<10} " + " ".join(f"{n[:26]:>26}" for n in names[1:]))
    worst: dict[str, float] = {}
    for serial in serials:
        cells = []
        for j, name in enumerate(names[1:], start=1):
            got = [d[j]["per_sensor"].get(serial) for d in by_draw]
            ref = [d[0]["per_sensor"].get(serial) for d in by_draw]
            if any(g is None for g in got) or any(r is None for r in ref):
                cells.append(f"{'dropped':>26}")
                continue
            ratio = math.sqrt(sum(g["sq_err"] for g in got) / sum(r["sq_err"] for r in ref))
            each = [g["rmse_ug"] / r["rmse_ug"] for g, r in zip(got, ref, strict=True)]
            worst[name] = max(worst.get(name, 0.0), ratio)
            cells.append(f"×{ratio:.3f} ({min(each):.3f}–{max(each):.3f})".rjust(26))
        print(f"{serial:<10} " + " ".join(cells))
    for j, name in enumerate(names[1:], start=1):
        hours = [d[j]["sim_s"] / 3600.0 for d in by_draw]
        past = sum(d[j]["per_sensor"][s]["rmse_ug"] / d[0]["per_sensor"][s]["rmse_ug"]
                   > EQUAL_ACCURACY for d in by_draw for s in serials
                   if s in d[j]["per_sensor"] and s in d[0]["per_sensor"])
        pooled = [pooled_rmse_ug(d[j]["per_sensor"]) / pooled_rmse_ug(d[0]["per_sensor"])
                  for d in by_draw]
        print(f"{name:<26} campaign {min(hours):.2f}–{max(hours):.2f} h "
              f"(×{min(hours) / SEED_HOURS_PER_SENSOR:.3f}–"
              f"×{max(hours) / SEED_HOURS_PER_SENSOR:.3f} of {SEED_HOURS_PER_SENSOR} h), "
              f"pooled ×{min(pooled):.3f}–×{max(pooled):.3f}, worst sensor over the draws "
              f"×{worst.get(name, math.nan):.3f}, sensor-draws past ×{EQUAL_ACCURACY:.2f}: "
              f"{past} of {len(by_draw) * n_sensors}")


if __name__ == "__main__":
    raise SystemExit(main())
