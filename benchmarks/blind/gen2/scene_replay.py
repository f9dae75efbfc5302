"""A case's scene under fresh noise draws: is a wrong name a tail draw or the test's bias?

    python -m benchmarks.blind.gen2.scene_replay --realdata DIR --out OUT --cases 0013,0123
                                                 [--draws 400] [--multiple M] [--skip-own]
                                                 [--first-stage] [--schedule NAME]

For each case of a second-generator run (OUT/keys), ``--draws`` recordings of the same scene
and sensor are drawn (the case's protocol, schedule, setpoints, visiting order, noise pools
and pattern; only the noise draws differ: draw k uses the record seed ``seed + 7919·k``, so
draw 0 is the case's own recording) with the case's effect at ``--multiple`` times its
minimum detectable size (default: the case's own multiple; 0: no effect, a null of that
scene), and each is diagnosed as ``run`` does (n_null 400, α 0.005). ``--skip-own`` starts at
k = 1. Printed per case: the top findings' counts and every draw where ``outlier`` is among
the findings, with its p. A name the test gives at its nominal rate on the scene without the
effect, and not more often with it, is a tail draw of a calibrated test
(docs/benchmarks.md, "Wrong names at 1x on min12 schedules").

``--schedule NAME``: the same scenes on another schedule (``dense24``, say): how much of what
is seen belongs to the schedule.

``--first-stage``: no diagnosis; each draw's outlier statistic at the first stage
(``outlier_oracle.first_stage_stats``: every reading against the base model, and the tail ν
its null takes), pooled over the cases and draws: the share of readings beyond χ²₃'s upper
1e-2, 1e-3, 1e-4 points against that level, the share of draws with a finite ν, and the
noise scale the diagnosis whitens by (``build_problem``) over the scatter the generator draws
on the plateaus without vibration, for the axes across the reference (placement adds
ρ²(1 − f_a²)) and the axis along it, per draw's median (10 / 50 / 90 % over the draws); and
the tail of the sensor pool's capture means at the cases' sample counts (excess kurtosis,
the share of means beyond 4 sd against a Gaussian's).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import tempfile
from pathlib import Path

import numpy as np
from scipy import stats as sps

from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.outlier_oracle import case_protocol, first_stage_stats
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.discrepancy.level import ALPHA, N_NULL
from calibration.discrepancy.problem import build_problem
from calibration.recording import read_recording, write_recording


def _case(out: Path, case: str, schedule: str | None):
    key = json.loads((out / "keys" / f"{case}.json").read_text())
    proto = case_protocol(key)
    if schedule:
        proto = dataclasses.replace(proto, schedule=schedule)
    return key, proto, key["pattern"], int(key["seed"])


def replay(out: Path, case: str, pools, draws: int, multiple: float | None, first: int,
           tmp: Path, schedule: str | None = None) -> dict:
    key, proto, pat, seed = _case(out, case, schedule)
    sensor = draw_sensor(np.random.default_rng(seed))  # generate.build's first draw
    mult = key["multiple"] if multiple is None else multiple
    eid = key["effect"] if mult else None
    m = key["magnitude"] * mult / key["multiple"] if mult else 0.0
    scene = sim.scene
    # The case's scene (its own seed: the visiting order of an irregular protocol) under
    # the record seed's noise stream.
    sim.scene = lambda p, e, mm, pt, _s, die_tau_s=None: scene(p, e, mm, pt, seed, die_tau_s)
    tops: collections.Counter = collections.Counter()
    named = []
    try:
        for k in range(first, first + draws):
            write_recording(tmp / "r.csv",
                            sim.record(proto, sensor, pools, eid, m, pat, seed + 7919 * k))
            d = json.loads(diagnose(read_recording(tmp / "r.csv"), seed=int(case),
                                    n_null=N_NULL, alpha=ALPHA).to_json())
            f = d.get("findings") or []
            tops[f[0]["effect"] if f else None] += 1
            for x in f:
                if x["effect"] == "outlier":
                    named.append({"draw": k, "p": x["evidence"]["p_value"],
                                  "steps": x["where"].get("steps"), "axes": x["axes"],
                                  "top": f[0]["effect"]})
    finally:
        sim.scene = scene
    return {"case": case, "effect": key["effect"], "protocol": key["protocol"],
            "schedule": proto.schedule, "multiple": mult, "draws": draws, "first": first,
            "top": {str(k): v for k, v in tops.most_common()},
            "outlier_named": len(named), "outliers": named}


def capture_mean_tail(pools, n: int, draws: int = 20000) -> dict:
    """Excess kurtosis and P(|z| > 4) of the sensor pool's capture means of n samples."""
    rng = np.random.default_rng(0)
    m = np.array([pools.block(rng, "sensor", n).mean(0) for _ in range(draws)])
    z = (m / m.std(0)).ravel()
    return {"n": n, "excess_kurtosis": round(float(sps.kurtosis(z)), 2),
            "beyond_4sd": float(np.mean(np.abs(z) > 4)),
            "gaussian_beyond_4sd": float(2 * sps.norm.sf(4))}


def first_stage(out: Path, cases: list[str], pools, draws: int, first: int,
                tmp: Path, schedule: str | None = None) -> dict:
    ts, nus, across, along, ns = [], [], [], [], set()
    scene = sim.scene
    try:
        for case in cases:
            _key, proto, pat, seed = _case(out, case, schedule)
            sensor = draw_sensor(np.random.default_rng(seed))
            ns.add(proto.n_samples)
            sc = scene(proto, None, 0.0, pat, seed)
            true = sim.reading_sigma_g(proto, pools, sc)
            quiet = sc.vib_sd_g == 0
            sim.scene = (lambda p, e, mm, pt, _s, die_tau_s=None, seed=seed:
                         scene(p, e, mm, pt, seed, die_tau_s))
            for k in range(first, first + draws):
                write_recording(tmp / "r.csv",
                                sim.record(proto, sensor, pools, None, 0.0, pat,
                                           seed + 7919 * k))
                rec = read_recording(tmp / "r.csv")
                t, nu = first_stage_stats(rec)
                ts.append(t)
                nus.append(nu)
                ratio = (1.0 / build_problem(rec).w).reshape(-1, 3) / true
                ac = (1.0 - sc.ref_g**2) > 0.5
                across.append(float(np.median(ratio[quiet][ac[quiet]])))
                along.append(float(np.median(ratio[quiet][~ac[quiet]])))
    finally:
        sim.scene = scene
    t_all = np.concatenate(ts)
    beyond = {f"{q:g}": [int(np.sum(t_all > sps.chi2.isf(q, 3))), round(q * t_all.size, 2)]
              for q in (1e-2, 1e-3, 1e-4)}
    return {"cases": cases, "schedule": schedule or "the cases'", "draws": draws,
            "readings": int(t_all.size),
            "beyond_chi2_3_level_observed_expected": beyond,
            "finite_nu": f"{int(np.sum(np.isfinite(nus)))}/{len(nus)}",
            "sigma_over_true_across_q10_50_90": np.round(np.quantile(across, [.1, .5, .9]),
                                                         2).tolist(),
            "sigma_over_true_along_q10_50_90": np.round(np.quantile(along, [.1, .5, .9]),
                                                        2).tolist(),
            "capture_mean_tail": [capture_mean_tail(pools, n) for n in sorted(ns)]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cases", required=True, help="comma-separated case ids of OUT/keys")
    ap.add_argument("--draws", type=int, default=400)
    ap.add_argument("--multiple", type=float, default=None,
                    help="the effect's size in minimum detectable sizes (0: none; "
                         "default: the case's own)")
    ap.add_argument("--skip-own", action="store_true", help="start at draw 1, not the case's")
    ap.add_argument("--first-stage", action="store_true",
                    help="no diagnosis: the outlier statistic's tail and the noise scale on "
                         "null draws of the cases' scenes")
    ap.add_argument("--schedule", default=None, help="replace the cases' schedule")
    a = ap.parse_args(argv)
    pools = load_pools(realdata_dir(a.realdata))
    with tempfile.TemporaryDirectory() as tmp:
        if a.first_stage:
            print(json.dumps(first_stage(a.out, a.cases.split(","), pools, a.draws,
                                         int(a.skip_own), Path(tmp), a.schedule)))
            return 0
        total = 0
        for case in a.cases.split(","):
            r = replay(a.out, case, pools, a.draws, a.multiple, int(a.skip_own), Path(tmp),
                       a.schedule)
            total += r["outlier_named"]
            print(json.dumps(r), flush=True)
        print(json.dumps({"outlier_named_total": total}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
