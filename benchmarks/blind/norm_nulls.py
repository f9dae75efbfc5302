"""False alarms of ``diagnose`` on norm-mode nulls with a noisy temperature channel (issue 10).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.norm_nulls [--n 120]

Each case: its own sensor (``SensorTruth.adxl355_typical``) and seed, no effect, recorded
without ``ref_*`` (norm mode). The protocols cycle through: one-way −40…60 °C and up-down,
chamber PV noise 0.1 °C (chamber_c only, die lag 30 s) or the sensor's own channel
(sensor_c, 0.1 °C per sample), 20- or 60-min soaks. A false alarm is ``mismatch`` true.
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
PROTOCOLS = [  # (name, setpoints, columns, soak_min)
    ("oneway_chamber_0.1C", ONE_WAY, ("chamber_c",), 20.0),
    ("updown_chamber_0.1C", UP_DOWN, ("chamber_c",), 20.0),
    ("oneway_sensor_c", ONE_WAY, ("sensor_c",), 60.0),
    ("updown_chamber_0.1C_60min", UP_DOWN, ("chamber_c",), 60.0),
]


def case(k: int, n_null: int) -> dict:
    name, setpoints, columns, soak = PROTOCOLS[k % len(PROTOCOLS)]
    truth = SensorTruth.adxl355_typical(seed=7000 + k)
    rec = simulate_campaign(truth, setpoints, seed=17000 + k, soak_min=soak,
                            physics=replace(RigPhysics(), pv_noise_c=0.1, die_tau_s=30.0),
                            temperature_columns=columns)
    rec = Recording.from_columns({c: v for c, v in rec.columns.items()
                                  if not c.startswith("ref_")})
    d = diagnose(rec, n_null=n_null, seed=k)
    return {"case": k, "protocol": name, "mode": d.mode, "mismatch": d.mismatch,
            "findings": [f.effect for f in d.findings]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=120)
    ap.add_argument("--n-null", type=int, default=200)
    ap.add_argument("--out", default="benchmarks/blind/results-norm-nulls.json")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = [case(k, a.n_null) for k in range(a.n)]
    fa = sum(bool(r["mismatch"]) for r in rows)
    lo, hi = clopper_pearson(fa, len(rows))
    by = {p[0]: [sum(bool(r["mismatch"]) for r in rows if r["protocol"] == p[0]),
                 sum(r["protocol"] == p[0] for r in rows)] for p in PROTOCOLS}
    res = {"false_alarms": fa, "n": len(rows), "rate": fa / len(rows), "ci95": [lo, hi],
           "by_protocol": by, "flagged_findings": [r for r in rows if r["mismatch"]],
           "wall_s": round(time.perf_counter() - t0, 1),
           "command": "OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.norm_nulls "
                      f"--n {a.n} --n-null {a.n_null}"}
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
