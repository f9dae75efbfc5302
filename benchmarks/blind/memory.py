"""Peak memory of ``diagnose`` against ``calibrate`` on a long recording (issue 10).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.memory [--rows 100000]

Builds one twin campaign (11 steps, Table 1 repeated to reach ``--rows`` readings), writes
it to a temporary CSV, then runs ``calibrate`` (``fit_campaign``) and ``diagnose`` each in
its own process and reports the peak RSS (``ru_maxrss``) and wall time of each, and the
diagnose figure per row.
"""

from __future__ import annotations

import argparse
import gc
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, resource, sys, time
from calibration.recording import read_recording
rec = read_recording(sys.argv[2])
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
if sys.argv[1] == "calibrate":
    from calibration.thermal import fit_campaign
    fit_campaign(rec)
else:
    from calibration.discrepancy import diagnose
    diagnose(rec, n_null=int(sys.argv[3]))
print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "after_read_mb": base / 1024, "wall_s": time.perf_counter() - t0}))
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--n-null", type=int, default=200)
    a = ap.parse_args(argv)
    import numpy as np

    from calibration.recording import write_recording
    from calibration.schedules import table1
    from simulators.campaign_sim import simulate_campaign
    from simulators.truth import SensorTruth

    setpoints = [float(t) for t in range(-40, 61, 10)]
    reps = max(1, a.rows // (len(setpoints) * 24))
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=1), setpoints,
                            np.tile(table1(), (reps, 1)), soak_min=30.0, seed=2)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.csv"
        write_recording(path, rec)
        n_rows = len(rec)
        del rec  # the children read the CSV; the parent must not hold a copy while they run
        gc.collect()
        out = {"rows": n_rows, "n_null": a.n_null}
        for what in ("calibrate", "diagnose"):
            r = subprocess.run([sys.executable, "-c", CHILD, what, str(path), str(a.n_null)],
                               capture_output=True, text=True, check=False)
            if r.returncode != 0:
                out[what] = {"error": r.stderr.strip().splitlines()[-1:]}
                continue
            out[what] = json.loads(r.stdout.strip().splitlines()[-1])
        if "peak_rss_mb" in out.get("diagnose", {}):
            d = out["diagnose"]
            d["kb_per_row"] = round((d["peak_rss_mb"] - d["after_read_mb"]) * 1024 / n_rows, 2)
        if "peak_rss_mb" in out.get("diagnose", {}) and "peak_rss_mb" in out.get("calibrate", {}):
            out["diagnose_over_calibrate_peak"] = round(
                out["diagnose"]["peak_rss_mb"] / out["calibrate"]["peak_rss_mb"], 2)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
