"""A twin that carries its recording's effects, held against new campaigns of the sensor.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.twin_effects \
        [--sensors 30] [--out OUT.json]

For each sensor (its own seed) and each kind of effect — ``scale_nonlinearity`` (K2 of
100–200 µg/g² on one axis), ``cross_coupling`` (one axis pair, 100–200 µg/g²),
``thermal_hysteresis`` (20–40 µg on one axis, an up-down staircase) and ``none`` — a twin is
fitted (``twin fit``) to one campaign of the offline twin rig (6 plateaus, Table 1 in a
balanced order, 30-min soaks) with its effects (``fit_twin``) and without them
(``--no-effects``), and held (``diagnose --against``, refit diagnosis on) against

* a second campaign of the same sensor (``same``: a false alarm if called a mismatch);
* a campaign of the sensor with the effect 1.3× as large (``grown``: found if a mismatch).

Scored per kind: the share of twins that carry the true effect, false alarms on ``same``
with a Clopper–Pearson 95 % interval (with and without the effects), and ``grown`` found
(with the effects: named as the twin's effect that moved).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_fit import fit_twin
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY_C = (-40.0, -20.0, 0.0, 20.0, 40.0, 60.0)
UP_DOWN_C = (-40.0, -10.0, 20.0, 60.0, 30.0, 0.0, -30.0)
KINDS = ("scale_nonlinearity", "cross_coupling", "thermal_hysteresis", "none")
GROWN = 1.3


def effect_for(kind: str, rng: np.random.Generator, scale: float = 1.0) -> list[object]:
    axis = int(rng.integers(0, 3))
    size = float(rng.uniform(1.0, 2.0))
    if kind == "scale_nonlinearity":
        k2 = np.zeros(3)
        k2[axis] = scale * size * 100e-6 * rng.choice([-1.0, 1.0])
        return [fx.ScaleNonlinearity(k2_per_g=k2, k3_per_g2=np.zeros(3))]
    if kind == "cross_coupling":
        k = {f"k_{q}_per_g": 0.0 for q in ("xy", "xz", "yz")}
        k[f"k_{('xy', 'xz', 'yz')[axis]}_per_g"] = scale * size * 100e-6
        return [fx.CrossCoupling(**k)]
    if kind == "thermal_hysteresis":
        h = np.zeros(3)
        h[axis] = scale * size * 20e-6
        return [fx.ThermalHysteresis(h_g=h)]
    return []


def campaign(truth: SensorTruth, kind: str, seed: int):
    setpoints = UP_DOWN_C if kind == "thermal_hysteresis" else ONE_WAY_C
    return simulate_campaign(truth, list(setpoints), seed=seed, soak_min=30.0,
                             position_order="balanced", position_order_seed=seed)


def sensor(k: int, kind: str) -> dict:
    # The same draws of the effect for the fitted and the grown campaign (one rng state).
    truth = SensorTruth.adxl355_typical(seed=7000 + k)
    truth.effects = effect_for(kind, np.random.default_rng(k))
    grown = SensorTruth.adxl355_typical(seed=7000 + k)
    grown.effects = effect_for(kind, np.random.default_rng(k), GROWN)
    rec = campaign(truth, kind, 10 * k + 1)
    twin, report = fit_twin(rec)
    bare, _ = fit_twin(rec, effects=False)
    same = campaign(truth, kind, 10 * k + 2)
    row = {"sensor": k, "kind": kind, "carried": [e["effect"] for e in twin.effects],
           "worst_plateau_rms_over_noise": report["worst_plateau_rms_over_noise"]}
    d = diagnose_against(same, twin, seed=k)
    row["same"] = {"mismatch": d.mismatch, "findings": [f["effect"] for f in d.findings]}
    d0 = diagnose_against(same, bare, seed=k)
    row["same_bare"] = {"mismatch": d0.mismatch, "findings": [f["effect"] for f in d0.findings]}
    if kind != "none":
        g = diagnose_against(campaign(grown, kind, 10 * k + 3), twin, seed=k)
        row["grown"] = {"mismatch": g.mismatch, "effect_moved": bool(g.shift.get("effects_moved")),
                        "findings": [f["effect"] for f in g.findings]}
    return row


def summarise(rows: list[dict]) -> dict:
    out: dict = {}
    for kind in KINDS:
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        n = len(rs)
        fa = sum(bool(r["same"]["mismatch"]) for r in rs)
        fa0 = sum(bool(r["same_bare"]["mismatch"]) for r in rs)
        entry = {"n": n,
                 "carried": sum(kind in r["carried"] for r in rs) if kind != "none"
                 else sum(bool(r["carried"]) for r in rs),
                 "false_alarms": [fa, list(clopper_pearson(fa, n))],
                 "false_alarms_without_effects": [fa0, list(clopper_pearson(fa0, n))],
                 "worst_plateau_rms_over_noise_median": float(np.median(
                     [r["worst_plateau_rms_over_noise"] for r in rs]))}
        if kind != "none":
            entry["grown_found"] = sum(bool(r["grown"]["mismatch"]) for r in rs)
            entry["grown_named_as_the_twins_effect"] = sum(r["grown"]["effect_moved"] for r in rs)
        out[kind] = entry
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", type=int, default=30)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    t0 = time.time()
    rows = [sensor(k, kind) for kind in KINDS for k in range(args.sensors)]
    res = {"summary": summarise(rows), "rows": rows, "seconds": round(time.time() - t0, 1)}
    text = json.dumps(res, indent=1)
    if args.out:
        args.out.write_text(text)
    print(json.dumps(res["summary"], indent=1))
    print(f"{res['seconds']} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
