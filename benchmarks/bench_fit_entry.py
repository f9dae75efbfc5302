"""The one fit entry: the service and ``soakcal calibrate`` on the same campaign, and its cost.

    python benchmarks/bench_fit_entry.py [--repeats 3]

For three simulated campaigns (an 11-step soak campaign with 60 min soaks; 3 steps
with 20 min soaks, die τ 600 s, whose die still creeps during each sweep; the same
rows with step numbers only, no setpoint) it fits the rows as the service does
(``service.engine.calibrate.calibrate_columns``) and as ``soakcal calibrate`` does
(the recording written and read back, ``calibration.cli.run_calibrate --json``),
and prints each one's decision (kind, method) and whether the two model files'
polynomials, temperature blocks and notes are identical. Then the time of
``calibration.fitting.fit`` against the step solver alone
(``calibration.thermal.fit_campaign``) on the 11-step campaign: what capture means,
segmentation, the gate's plan and its checks cost on top (best of ``--repeats``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from calibration.cli import run_calibrate  # noqa: E402
from calibration.fitting import fit  # noqa: E402
from calibration.recording import Recording, write_recording  # noqa: E402
from calibration.thermal import fit_campaign  # noqa: E402
from service.engine.calibrate import calibrate_columns  # noqa: E402
from simulators.campaign_sim import RigPhysics, simulate_campaign  # noqa: E402
from simulators.truth import SensorTruth  # noqa: E402


def fixtures() -> dict[str, Recording]:
    soak60 = simulate_campaign(SensorTruth.adxl355_typical(1), seed=1)
    soak20 = simulate_campaign(SensorTruth.adxl355_typical(12), (-20.0, 20.0, 60.0),
                               soak_min=20.0, seed=13, physics=RigPhysics(die_tau_s=600.0))
    numbered = Recording.from_columns({k: v for k, v in soak20.columns.items()
                                       if k != "setpoint_c"})
    return {"11 steps, 60 min soaks": soak60, "3 steps, 20 min soaks": soak20,
            "3 steps, 20 min soaks, no setpoint_c": numbered}


def both_ways(rec: Recording, tmp: Path) -> tuple[str, str, bool]:
    """(service's kind/method, calibrate's method, identical model polynomials)."""
    columns = {k: [float(v) for v in col] for k, col in rec.columns.items()}
    row = calibrate_columns(columns, {"recording": "campaign.csv"})
    src, out = tmp / "recording.csv", tmp / "model.json"
    write_recording(src, rec)
    ns = argparse.Namespace(recording=str(src), output=str(out), json=True, report_dir=None,
                            method=None)
    with contextlib.redirect_stdout(io.StringIO()) as buf:
        assert run_calibrate(ns) == 0
    doc = json.loads(buf.getvalue())
    cli = json.loads(out.read_text())
    same = all(cli[k] == row.model[k] for k in ("polynomial", "temperature", "notes"))
    return f"{row.fit.kind}/{row.fit.method}", str(doc["method"]), same


def best_time(fn: object, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()  # type: ignore[operator]
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    recs = fixtures()
    print("| campaign | service (kind/method) | calibrate (method) | same model |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, rec in recs.items():
            svc, cli, same = both_ways(rec, Path(tmp))
            print(f"| {name} | {svc} | {cli} | {'yes' if same else 'NO'} |")
    rec = recs["11 steps, 60 min soaks"]
    t_entry = best_time(lambda: fit(rec), a.repeats)
    t_solver = best_time(lambda: fit_campaign(rec), a.repeats)
    print(f"\nfitting.fit {t_entry * 1e3:.0f} ms, thermal.fit_campaign alone "
          f"{t_solver * 1e3:.0f} ms ({len(rec)} rows, best of {a.repeats})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
