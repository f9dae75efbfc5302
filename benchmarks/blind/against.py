"""Twin-against-recording benchmark: ``diagnose --against`` on stale models and wrong twins.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.against [--sensors 40] [--refit]

For each sensor (its own seed) two protocols of the offline twin:

* ``oneway`` (sensor_c + chamber_c, 30-min soaks, −40…60 °C): a model from ``calibrate`` on
  one recording, held against a second recording of
  - the same sensor (null), the sensor with its y or x bias aged 0.4 mg (``stale_bias``),
    its z scale factor moved 300 ppm (``stale_scale``), another sensor (``other_sensor``);
* ``chamber`` (chamber_c only, 20-min soaks, die lag 300…1800 s): a twin from ``twin fit``
  on one recording, held against a second recording of the same rig and sensor (null),
  and the same twin with its die lag set to ⅓× or 3× the fitted one (``wrong_lag``).

Scored: false alarms on the nulls (``mismatch`` true) with a Clopper–Pearson 95 % interval;
on the other cases the share found, the share whose corrected twin has a held-out RMS (whole
plateaus, same rows) at least 50 % below the given one's, and whether the named finding is
the right one (``parameter_shift`` with the moved parameter; ``thermal_lag`` for the rig).
``--refit`` adds the refit diagnosis (catalogue effects) to every verdict (slower).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_file import Twin
from calibration.discrepancy.twin_fit import fit_twin
from calibration.thermal import fit_campaign
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = tuple(float(t) for t in range(-40, 61, 10))
AGED_BIAS_G = 0.4e-3
MOVED_SCALE = 300e-6


def oneway(truth: SensorTruth, seed: int):
    return simulate_campaign(truth, ONE_WAY, seed=seed, soak_min=30.0)


def chamber(truth: SensorTruth, seed: int, tau_s: float):
    return simulate_campaign(truth, ONE_WAY, seed=seed, soak_min=20.0,
                             physics=replace(RigPhysics(), die_tau_s=tau_s),
                             temperature_columns=("chamber_c",))


def cases_for(k: int, refit: bool, n_null: int) -> list[dict]:
    rng = np.random.default_rng(1000 + k)
    truth = SensorTruth.adxl355_typical(seed=5000 + k)
    out = []

    def run(kind: str, rec, given: Twin, expect: str | None, param: str | None = None) -> None:
        d = diagnose_against(rec, given, refit=refit, n_null=n_null, seed=k)
        found = [f["effect"] for f in d.findings]
        ho = d.heldout
        right = False
        if expect == "parameter_shift":
            right = bool(found) and found[0] == "parameter_shift" and param in d.shift[
                "parameters"]
        elif expect == "thermal_lag":
            right = "thermal_lag" in found
        out.append({"sensor": k, "kind": kind, "mismatch": d.mismatch, "findings": found,
                    "right": right, "rmse_given_ug": d.rmse_given_ug,
                    "heldout_given_ug": ho.get("rmse_given_ug"),
                    "heldout_corrected_ug": ho.get("rmse_corrected_ug"),
                    "shift": d.shift.get("parameters")})

    model = Twin(fit_campaign(oneway(truth, 10 * k + 1)).model)
    run("null_model", oneway(truth, 10 * k + 2), model, None)
    axis = int(rng.integers(0, 2))
    aged = replace(truth, coeffs=truth.coeffs.copy())
    aged.coeffs[axis, 0] += AGED_BIAS_G * rng.choice([-1.0, 1.0])
    run("stale_bias", oneway(aged, 10 * k + 3), model, "parameter_shift", f"d_b{'xy'[axis]}_ug")
    moved = replace(truth, coeffs=truth.coeffs.copy())
    moved.coeffs[5, 0] += MOVED_SCALE * rng.choice([-1.0, 1.0])
    run("stale_scale", oneway(moved, 10 * k + 4), model, "parameter_shift", "d_sz_ppm")
    other = SensorTruth.adxl355_typical(seed=9000 + k)
    run("other_sensor", oneway(other, 10 * k + 5), model, "parameter_shift", "d_bx_ug")
    tau = float(np.exp(rng.uniform(np.log(300.0), np.log(1800.0))))
    twin, _ = fit_twin(chamber(truth, 10 * k + 6, tau))
    run("null_twin", chamber(truth, 10 * k + 7, tau), twin, None)
    if twin.die_tau_s:
        factor = 1 / 3 if k % 2 else 3.0
        wrong = replace(twin, die_tau_s=twin.die_tau_s * factor, die_tau_sd_s=None)
        run("wrong_lag", chamber(truth, 10 * k + 8, tau), wrong, "thermal_lag")
    return out


def summarise(rows: list[dict]) -> dict:
    res: dict = {}
    nulls = [r for r in rows if r["kind"].startswith("null")]
    fa = sum(bool(r["mismatch"]) for r in nulls)
    lo, hi = clopper_pearson(fa, len(nulls))
    res["false_alarms"] = {"k": fa, "n": len(nulls), "rate": fa / max(len(nulls), 1),
                           "ci95": [lo, hi],
                           "by_kind": {k: [sum(bool(r["mismatch"]) for r in nulls
                                               if r["kind"] == k),
                                           sum(r["kind"] == k for r in nulls)]
                                       for k in ("null_model", "null_twin")}}
    for kind in ("stale_bias", "stale_scale", "other_sensor", "wrong_lag"):
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        found = sum(bool(r["mismatch"]) for r in rs)
        right = sum(r["right"] for r in rs)
        halved = sum(r["heldout_corrected_ug"] is not None and r["heldout_given_ug"]
                     and r["heldout_corrected_ug"] <= 0.5 * r["heldout_given_ug"] for r in rs)
        red = [1 - r["heldout_corrected_ug"] / r["heldout_given_ug"] for r in rs
               if r["heldout_given_ug"]]
        res[kind] = {"n": len(rs), "found": found, "found_ci95": clopper_pearson(found, len(rs)),
                     "right_finding": right, "heldout_halved": halved,
                     "heldout_reduction_median_percent": round(100 * float(np.median(red)), 1),
                     "heldout_reduction_min_percent": round(100 * float(np.min(red)), 1)}
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", type=int, default=40)
    ap.add_argument("--refit", action="store_true", help="include the refit diagnosis")
    ap.add_argument("--n-null", type=int, default=100)
    ap.add_argument("--out", default="benchmarks/blind/results-against.json")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows: list[dict] = []
    for k in range(args.sensors):
        rows += cases_for(k, args.refit, args.n_null)
    res = summarise(rows)
    res["wall_s"] = round(time.perf_counter() - t0, 1)
    res["command"] = ("OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.against "
                      f"--sensors {args.sensors}" + (" --refit" if args.refit else ""))
    Path(args.out).write_text(json.dumps({"summary": res, "cases": rows}, indent=1,
                                         default=float) + "\n")
    print(json.dumps(res, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
