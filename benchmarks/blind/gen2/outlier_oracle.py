"""Is an `outlier` case the diagnosis missed detectable against the noise the generator drew?

    python -m benchmarks.blind.gen2.outlier_oracle --realdata DIR --out OUT [--cases 0189,0287]
                                                    [--nulls 30]

For each `outlier` case of a second-generator run (OUT/keys, OUT/cases; by default the cases
at 2× whose top finding in OUT/diagnoses.json is not `outlier`), ``--nulls`` recordings of
the same scene and sensor are drawn afresh without the effect (the case's protocol,
schedule, setpoints and noise pools; only the noise draws differ) and each is given the
statistic ``diagnose``'s outlier test reads at its first stage (the leave-one-reading-out
statistic against the base model, ``stats.row_stats``). Printed per case: the case's own
largest statistic among its two outlier readings, how many of the null readings reach it,
the null's largest statistic per recording (median, 90 % and 99 % over the recordings), the
tail ν the outlier test's null takes on the case (``stats.reading_tail_dof`` at its point
estimate) and the same estimate on each null recording (10 %, 25 %, 50 % quantiles; ∞ where
the ratio is χ²₃'s), and on all null readings pooled. An oracle that knew the generator's
noise law would call the case when no null reading comes near it (docs/benchmarks.md,
"An outlier does not set its plateau's noise").
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import fields
from pathlib import Path

import numpy as np

from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.protocol import Protocol2
from benchmarks.blind.gen2.reading_tail import first_stage_row_stats
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import stats
from calibration.recording import Recording, read_recording, write_recording


def first_stage_stats(rec: Recording) -> tuple[np.ndarray, float]:
    """(the per-reading statistic of the outlier test's first stage, its null's tail ν)."""
    t, g = first_stage_row_stats(rec)
    return t, stats.reading_tail_dof(t, g, stats.NULL_TAIL_Z)


def case_protocol(key: dict) -> Protocol2:
    det = dict(key["protocol_detail"])
    tuples = {"setpoints_c", "columns", "vib_sd_g"}
    return Protocol2(**{f.name: (tuple(det[f.name]) if f.name in tuples else det[f.name])
                        for f in fields(Protocol2) if f.name in det})


def oracle(out: Path, case: str, pools, n_nulls: int, tmp: Path) -> dict:
    key = json.loads((out / "keys" / f"{case}.json").read_text())
    proto, pat, seed = case_protocol(key), key["pattern"], int(key["seed"])
    sensor = draw_sensor(np.random.default_rng(seed))  # generate.build's first draw
    t_case, nu_case = first_stage_stats(read_recording(out / "cases" / f"{case}.csv"))
    t_key = float(np.max(t_case[pat["rows"]]))
    scene = sim.scene
    # The case's scene (its own seed) under fresh noise draws (record's seed + 1 stream).
    sim.scene = lambda p, eid, m, pt, _s, die_tau_s=None: scene(p, eid, m, pt, seed, die_tau_s)
    try:
        pooled, maxes, nus = [], [], []
        for k in range(n_nulls):
            write_recording(tmp / "null.csv",
                            sim.record(proto, sensor, pools, None, 0.0, pat, seed + 7919 * (k + 1)))
            t, nu = first_stage_stats(read_recording(tmp / "null.csv"))
            pooled.append(t)
            maxes.append(float(t.max()))
            nus.append(nu)
    finally:
        sim.scene = scene
    t_all = np.concatenate(pooled)
    nu_q = np.sort(nus)[[int(q * (len(nus) - 1)) for q in (0.1, 0.25, 0.5)]]
    return {"case": case, "readings": int(t_case.size), "t_outlier": round(t_key, 1),
            "nu_case": round(nu_case, 1), "null_readings": int(t_all.size),
            "null_at_or_above": int(np.sum(t_all >= t_key)),
            "null_max_q50_q90_q99": [round(float(q), 1) for q in
                                     np.quantile(maxes, [0.5, 0.9, 0.99])],
            "nu_null_q10_q25_q50": [round(float(v), 1) for v in nu_q],
            "nu_null_pooled": round(stats.reading_tail_dof(t_all, 3, stats.NULL_TAIL_Z), 1)}


def missed(out: Path) -> list[str]:
    """The `outlier` cases at 2× whose top finding is not `outlier`."""
    diag = json.loads((out / "diagnoses.json").read_text())
    found = []
    for p in sorted((out / "keys").glob("*.json")):
        key = json.loads(p.read_text())
        if key.get("effect") != "outlier" or key.get("multiple") != 2.0:
            continue
        fnd = diag.get(p.stem, {}).get("findings", [])
        if not fnd or fnd[0].get("effect") != "outlier":
            found.append(p.stem)
    return found


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cases", default=None, help="comma-separated; default: the missed")
    ap.add_argument("--nulls", type=int, default=30)
    a = ap.parse_args(argv)
    pools = load_pools(realdata_dir(a.realdata))
    cases = a.cases.split(",") if a.cases else missed(a.out)
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            print(json.dumps(oracle(a.out, case, pools, a.nulls, Path(tmp))), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
