"""False alarms of ``diagnose`` on nulls across modes (issue 10: the false-alarm interval).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.blind.nulls [--n 1000]

Each case: its own simulated sensor (``SensorTruth.adxl355_typical``) and seed, no effect.
Case k runs protocol ``k mod 8``: reference and norm mode, one-way −40…60 °C and up-down,
chamber-only 0.1 °C PV noise (die 30 s behind the air) or the sensor's own channel, soaks
of 10, 20 or 60 min. A false alarm is ``mismatch`` true; the rate is reported with its
Clopper–Pearson 95 % interval, per protocol, and the flagged cases' findings (which test
fired) so that a cause can be looked for.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy import diagnose
from calibration.recording import Recording
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = tuple(float(t) for t in range(-40, 61, 10))
UP_DOWN = (-40.0, -20.0, 0.0, 20.0, 40.0, 60.0, 50.0, 30.0, 10.0, -10.0, -30.0)
CHAMBER = ("chamber_c",)
SENSOR = ("sensor_c",)
PROTOCOLS = [  # (name, setpoints, temperature columns, soak_min, reference recorded)
    ("ref_oneway_chamber_20min", ONE_WAY, CHAMBER, 20.0, True),
    ("norm_oneway_chamber_20min", ONE_WAY, CHAMBER, 20.0, False),
    ("ref_updown_chamber_10min", UP_DOWN, CHAMBER, 10.0, True),
    ("norm_updown_chamber_20min", UP_DOWN, CHAMBER, 20.0, False),
    ("ref_oneway_sensor_60min", ONE_WAY, SENSOR, 60.0, True),
    ("norm_oneway_sensor_60min", ONE_WAY, SENSOR, 60.0, False),
    ("ref_updown_chamber_60min", UP_DOWN, CHAMBER, 60.0, True),
    ("norm_updown_chamber_10min", UP_DOWN, CHAMBER, 10.0, False),
]


def case(k: int, n_null: int) -> dict:
    name, setpoints, columns, soak, with_ref = PROTOCOLS[k % len(PROTOCOLS)]
    truth = SensorTruth.adxl355_typical(seed=9000 + k)
    rec = simulate_campaign(truth, setpoints, seed=19000 + k, soak_min=soak,
                            physics=replace(RigPhysics(), pv_noise_c=0.1, die_tau_s=30.0),
                            temperature_columns=columns)
    if not with_ref:
        rec = Recording.from_columns({c: v for c, v in rec.columns.items()
                                      if not c.startswith("ref_")})
    d = diagnose(rec, n_null=n_null, seed=k)
    return {"case": k, "protocol": name, "mode": d.mode, "mismatch": d.mismatch,
            "findings": [{"effect": f.effect, "p_value": f.p_value, "where": f.where}
                         for f in d.findings] if d.mismatch else []}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--start", type=int, default=0, help="first case index (to resume)")
    ap.add_argument("--n-null", type=int, default=200)
    ap.add_argument("--out", default="benchmarks/blind/results-nulls.json")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    for k in range(a.start, a.start + a.n):
        rows.append(case(k, a.n_null))
        if len(rows) % 50 == 0:
            fa = sum(bool(r["mismatch"]) for r in rows)
            print(f"  {len(rows)} nulls, {fa} false alarms ({time.perf_counter() - t0:.0f} s)",
                  flush=True)
    fa = sum(bool(r["mismatch"]) for r in rows)
    lo, hi = clopper_pearson(fa, len(rows))
    by = {p[0]: [sum(bool(r["mismatch"]) for r in rows if r["protocol"] == p[0]),
                 sum(r["protocol"] == p[0] for r in rows)] for p in PROTOCOLS}
    res = {"false_alarms": fa, "n": len(rows), "rate": fa / len(rows), "ci95": [lo, hi],
           "by_protocol": by, "flagged": [r for r in rows if r["mismatch"]],
           "wall_s": round(time.perf_counter() - t0, 1),
           "command": "OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m "
                      f"benchmarks.blind.nulls --n {a.n} --start {a.start} --n-null {a.n_null}"}
    Path(a.out).write_text(json.dumps(res, indent=1, default=str) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k != "flagged"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
