"""Peak memory of ``diagnose`` against ``calibrate`` on a long recording (issue 10).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.blind.memory [--rows 100000]
        [--shape positions|samples] [--cli] [--csv PATH] [--only calibrate|diagnose]
        [--effect scale_nonlinearity --size 10] [--raw-cells] [--answer PATH]

Builds one twin campaign (11 steps) of about ``--rows`` readings, writes it to a CSV
(temporary unless ``--csv`` names one; an existing ``--csv`` is reused as it is), then runs
``calibrate`` and ``diagnose`` each in its own process and reports the peak RSS
(``ru_maxrss``, which includes reading the CSV), wall time and CPU time (user + sys, the
whole process: the figure to compare on a loaded machine) of each, and the diagnose
figure per row. Two shapes of a long recording:

* ``positions`` (default): Table 1 repeated to reach the rows, one averaged reading
  (n = 200) per position, so the positions grow with the rows;
* ``samples``: Table 1 once per step (24 positions), each position's capture written as
  raw samples (one row per sample at the sensor's 62.5 Hz, ``n`` = 1, no ``sd_*``): a
  streamed recording, many rows per position.

``--effect``/``--size`` conceal a catalogue effect in the sensor
(``benchmarks.blind.catalogue.make``, size in its unit, the pattern of signs drawn with seed
0): a recording ``diagnose`` finds a mismatch in, so its accepted terms and checks run at
that length (issue 22).

``--answer PATH`` writes ``diagnose``'s JSON there (after its peak is read), so that two
versions' answers on the same recording can be compared.

By default the CSV is read as the CLI reads it (``read_recording(path, raw_cells=False)``:
the text is not kept) and each child runs what ``calibration/cli.py`` runs after that:
``fitting.fit`` for ``calibrate``; the gate, ``placed_samples`` and ``diagnose`` for
``diagnose`` (issue 22: the ratio users see). ``--raw-cells`` gives the figure of the
sections before: the text kept (``read_recording(path)``), ``fit_campaign`` and
``diagnose``. ``--cli`` runs the commands a user runs (``soakcal calibrate --json`` with
its held-out refits and report, ``soakcal diagnose --json``) instead of the library calls.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import contextlib, io, json, os, resource, sys, tempfile, time
what, path, n_null, cli = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4] == "1"
answer, raw_cells = sys.argv[5], sys.argv[6] == "1"
doc = None
t0 = time.perf_counter()
if cli:
    from service.cli import main
    with tempfile.TemporaryDirectory() as tmp:
        argv = ([what, path, "--json", "-o", os.path.join(tmp, "model.json")]
                if what == "calibrate" else [what, path, "--json", "--n-null", str(n_null)])
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            code = main(argv)
        if code:
            raise SystemExit(f"{what} exited with {code}")
        doc = json.loads(out.getvalue())
    base = float("nan")
    extra = ({k: doc.get(k) for k in ("rmse_ug", "loo_rmse_ug", "loo_notes")}
             if what == "calibrate" else {"verdict": doc.get("verdict")})
elif raw_cells:  # the library calls on the CSV read with its text kept (before issue 22)
    from calibration.recording import read_recording
    rec = read_recording(path)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    if what == "calibrate":
        from calibration.thermal import fit_campaign
        fit_campaign(rec)
    else:
        from calibration.discrepancy import diagnose
        doc = diagnose(rec, n_null=n_null).to_dict()
    extra = {}
else:  # what the CLI runs (calibration/cli.py), without its report and model file
    from calibration.recording import read_recording
    rec = read_recording(path, raw_cells=False)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    if what == "calibrate":
        from calibration import fitting
        fitting.fit(rec)
    else:
        from calibration import gate
        from calibration.captures import capture_means, placed_samples
        from calibration.discrepancy import diagnose
        if gate.cannot_judge(rec) is not None:
            raise SystemExit("the gate refuses this recording")
        rec = placed_samples(rec, capture_means(rec))
        doc = diagnose(rec, n_null=n_null).to_dict()
    extra = {}
ru = resource.getrusage(resource.RUSAGE_SELF)
if answer and doc is not None:  # after the peak was read: the answer, to compare runs
    with open(answer, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1, sort_keys=True, ensure_ascii=False)
print(json.dumps({"peak_rss_mb": ru.ru_maxrss / 1024, "after_read_mb": base,
                  "wall_s": time.perf_counter() - t0, "cpu_s": ru.ru_utime + ru.ru_stime,
                  **extra}))
"""

WRITE = r"""
import sys
from benchmarks.blind.memory import long_recording
from calibration.recording import write_recording
path, rows, shape, effect, size = sys.argv[1:6]
write_recording(path, long_recording(int(rows), shape, effect or None, float(size)))
"""

SETPOINTS_C = [float(t) for t in range(-40, 61, 10)]


def long_recording(rows: int, shape: str, effect: str | None = None,
                   size: float = 0.0):  # -> Recording
    """About ``rows`` readings of one 11-step twin campaign in the given shape, with the
    catalogue ``effect`` of ``size`` (its unit) concealed when given."""
    import numpy as np

    from calibration.schedules import table1
    from simulators.campaign_sim import simulate_campaign
    from simulators.truth import SensorTruth

    truth = SensorTruth.adxl355_typical(seed=1)
    if effect:
        from benchmarks.blind.catalogue import draw_pattern, make
        from benchmarks.blind.protocols import PROTOCOLS

        protocol = PROTOCOLS["short_soak"]
        pattern = draw_pattern(np.random.default_rng(0), protocol, 0)
        truth.effects = [make(effect, size, pattern, protocol).effect]
    per_step = len(SETPOINTS_C) * 24
    if shape == "positions":
        reps = max(1, rows // per_step)
        return simulate_campaign(
            truth, SETPOINTS_C, np.tile(table1(), (reps, 1)), soak_min=30.0, seed=2
        )
    k = max(1, rows // per_step)  # samples per position
    rec = simulate_campaign(
        truth, SETPOINTS_C, table1(), soak_min=30.0, samples_per_position=k, seed=2
    )
    # Each averaged row back to the k samples it was the mean of.
    from benchmarks.blind.sample_nulls import as_raw_samples

    return as_raw_samples(rec, k, truth.odr_hz, np.random.default_rng(3))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--n-null", type=int, default=200)
    ap.add_argument("--shape", choices=("positions", "samples"), default="positions")
    ap.add_argument("--cli", action="store_true", help="run the soakcal commands")
    ap.add_argument("--csv", type=Path, help="keep (or reuse) the recording here")
    ap.add_argument("--only", choices=("calibrate", "diagnose"))
    ap.add_argument("--answer", type=Path, help="write diagnose's JSON here")
    ap.add_argument("--effect", help="a catalogue effect id concealed in the sensor")
    ap.add_argument("--size", type=float, default=0.0, help="its size, in its unit")
    ap.add_argument("--raw-cells", action="store_true",
                    help="library calls on the CSV read with its text kept (the old figure)")
    a = ap.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        path = a.csv or Path(tmp) / "long.csv"
        if not path.exists():
            # Written by a process of its own: Linux carries a process's peak RSS into the
            # ru_maxrss of a child it starts (across exec), so the children below would
            # report this one's peak of building the recording as their own (issue 22: a
            # calibrate "after read" of 1,016 MB against 472 MB on the CSV reused).
            subprocess.run([sys.executable, "-c", WRITE, str(path), str(a.rows), a.shape,
                            a.effect or "", str(a.size)], check=True)
        with open(path, encoding="utf-8") as fh:
            n_rows = sum(1 for _ in fh) - 1
        out = {"rows": n_rows, "shape": a.shape, "n_null": a.n_null, "cli": a.cli,
               "raw_cells": a.raw_cells,
               "effect": a.effect, "size": a.size}
        whats = (a.only,) if a.only else ("calibrate", "diagnose")
        for what in whats:
            r = subprocess.run(
                [
                    sys.executable,
                    "-c",
                    CHILD,
                    what,
                    str(path),
                    str(a.n_null),
                    "1" if a.cli else "0",
                    str(a.answer) if a.answer and what == "diagnose" else "",
                    "1" if a.raw_cells else "0",
                ],
                capture_output=True,
                text=True,
                check=False,
            )
            if r.returncode != 0:
                out[what] = {"error": r.stderr.strip().splitlines()[-1:]}
                continue
            out[what] = json.loads(r.stdout.strip().splitlines()[-1])
        d = out.get("diagnose", {})
        if "peak_rss_mb" in d and d.get("after_read_mb") == d.get("after_read_mb"):  # not NaN
            d["kb_per_row"] = round((d["peak_rss_mb"] - d["after_read_mb"]) * 1024 / n_rows, 2)
        if "peak_rss_mb" in d and "peak_rss_mb" in out.get("calibrate", {}):
            out["diagnose_over_calibrate_peak"] = round(
                d["peak_rss_mb"] / out["calibrate"]["peak_rss_mb"], 2
            )
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
