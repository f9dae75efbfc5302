"""``soakcal import`` and ``soakcal calibrate`` of a real-size thermal log: time and memory.

    python benchmarks/bench_import_speed.py --before-rev REV [--rows 2400000,100000]
        [--dataflash-rows N] [--work DIR] [--jobs 1]

Issue 20 ("Speed"): a PX4/ArduPilot thermal-calibration log is a board warmed for
30–60 min with the accelerometer logged at 0.4–1 kHz. For each row count this writes
the log of the issue's brief (``t,ax,ay,az,temp`` in s, m/s², °C at 1 kHz: a 20 → 65 °C
warm-up with τ = 600 s, bias drift 0.5/−0.3/0.8 mg per 10 °C plus a curvature on y,
2 mg noise, the temperature quantised at 0.0078 °C), then runs, each in its own
process, with the code of ``REV`` (``git archive``) and of this tree:

    soakcal import --format csv LOG -o REC --columns t=t,ax=ax,ay=ay,az=az,temp=temp
        --accel-unit m/s2 --temp-unit C --time-unit s
    soakcal calibrate REC -o MODEL

and prints wall time, user + system CPU time, peak RSS (GNU ``/usr/bin/time``) and exit
code of each (a log too short to warm refuses ``calibrate`` with exit 2), and
whether the two trees wrote the same bytes: the recording, the import's summary (its
output path aside), the calibrate report and the model (its ``created_utc`` aside).
With ``--dataflash-rows N``, also ``soakcal import --format dataflash`` of an N-message
``IMU`` log (1 kHz, written by ``tests/calibration/log_writers.py``) before and after.
One process at a time (``--jobs`` is accepted for uniformity and must be 1).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TIME = "/usr/bin/time"  # GNU time: -f "%e %U %S %M"
FS_HZ = 1000.0
G_M_S2 = 9.80665


def write_log(path: Path, n: int) -> None:
    """The brief's warm-up log: n samples at 1 kHz (seed 1, as the issue's figures)."""
    rng = np.random.default_rng(1)
    t = np.arange(n) / FS_HZ
    temp = 20 + 45 * (1 - np.exp(-t / 600))
    ax = 0.0005 * (temp - 20) / 10 + rng.normal(0, 2e-3, n)
    ay = -0.0003 * (temp - 20) / 10 + 1e-6 * (temp - 40) ** 2 + rng.normal(0, 2e-3, n)
    az = 1.0 + 0.0008 * (temp - 20) / 10 + rng.normal(0, 2e-3, n)
    temp_q = np.round((temp + rng.normal(0, 0.02, n)) / 0.0078) * 0.0078
    with path.open("w") as f:
        f.write("t,ax,ay,az,temp\n")
        np.savetxt(f, np.column_stack([t, ax * G_M_S2, ay * G_M_S2, az * G_M_S2, temp_q]),
                   fmt=["%.4f", "%.6f", "%.6f", "%.6f", "%.4f"], delimiter=",")


def timed(code: Path, argv: list[str], cwd: Path) -> dict[str, object]:
    """Run ``argv`` under ``code``, measured by GNU time (wall, user + system CPU, peak RSS).

    Not ``os.wait4`` from here: a child's peak RSS starts at this process's own (the
    kernel keeps the high-water mark across fork and exec), which is the size of the
    2.4 M-row log's arrays after writing it."""
    env = {**os.environ, "PYTHONPATH": str(code), "OPENBLAS_NUM_THREADS": "1"}
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tfile:
        proc = subprocess.run([TIME, "-f", "%e %U %S %M", "-o", tfile.name, sys.executable,
                               "-m", "service.cli", *argv], cwd=cwd, env=env,
                              capture_output=True, text=True)
        wall, user, system, peak_kb = tfile.read().split()[-4:]
    return {"wall_s": float(wall), "cpu_s": float(user) + float(system),
            "peak_mb": int(peak_kb) / 1024.0, "rc": proc.returncode, "stdout": proc.stdout,
            "stderr": proc.stderr}


def checkout(rev: str, dest: Path) -> Path:
    """The tree of ``rev`` (``git archive``), to run the code as it was."""
    dest.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest


def model_without_stamp(path: Path) -> str:
    doc = json.loads(path.read_text())

    def strip(x: object) -> object:
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if k != "created_utc"}
        if isinstance(x, list):
            return [strip(v) for v in x]
        return x

    return json.dumps(strip(doc), sort_keys=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before-rev", required=True, help="git revision of the 'before' code")
    ap.add_argument("--rows", default="2400000,100000", help="row counts, comma-separated")
    ap.add_argument("--work", type=Path, default=None, help="scratch folder (default: temp)")
    ap.add_argument("--jobs", type=int, default=1, help="must be 1: one process at a time")
    ap.add_argument("--dataflash-rows", type=int, default=0,
                    help="also import an ArduPilot DataFlash log of this many IMU messages")
    args = ap.parse_args(argv)
    if args.jobs != 1:
        ap.error("--jobs must be 1: the figures are of one process at a time")
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_import_"))
    work.mkdir(parents=True, exist_ok=True)
    trees = {"before": checkout(args.before_rev, work / "before_tree"), "after": ROOT}
    print(f"before = {args.before_rev}, after = this tree; work folder {work}")
    print("| rows | command | code | wall s | CPU s | peak RSS MB | exit |")
    print("|---|---|---|---|---|---|---|")
    for n in (int(x) for x in args.rows.split(",") if x):
        log = work / f"log_{n}.csv"
        if not log.exists():
            write_log(log, n)
        outputs: dict[str, dict[str, str]] = {}
        for name, code in trees.items():
            rec, model = work / f"rec_{n}_{name}.csv", work / f"model_{n}_{name}.json"
            imp = timed(code, ["import", "--format", "csv", str(log), "-o", str(rec),
                               "--columns", "t=t,ax=ax,ay=ay,az=az,temp=temp",
                               "--accel-unit", "m/s2", "--temp-unit", "C", "--time-unit", "s"],
                        work)
            cal = timed(code, ["calibrate", str(rec), "-o", str(model)], work)
            for label, r in (("import", imp), ("calibrate", cal)):
                print(f"| {n:,} | {label} | {name} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
                      f"{r['peak_mb']:.0f} | {r['rc']} |", flush=True)
            if imp["rc"] != 0:
                raise SystemExit(f"import ({name}) exited {imp['rc']}: {imp['stderr']}")

            def plain(text: object, rec: Path = rec, model: Path = model) -> str:
                """The output with this tree's own file names taken out."""
                return str(text).replace(rec.name, "REC").replace(model.name, "MODEL")

            outputs[name] = {
                "recording": hashlib.sha256(rec.read_bytes()).hexdigest(),
                "import summary": plain(imp["stdout"]),
                "calibrate report": plain(cal["stdout"]) + plain(cal["stderr"]),
                "model": plain(model_without_stamp(model)) if model.exists() else "(none)",
            }
        same = [k for k in outputs["before"] if outputs["before"][k] == outputs["after"][k]]
        differ = [k for k in outputs["before"] if k not in same]
        print(f"\n{n:,} rows: identical before/after: {', '.join(same) or 'nothing'}"
              + (f"; DIFFERENT: {', '.join(differ)}" if differ else "") + "\n")
    if args.dataflash_rows:
        dataflash(trees, work, args.dataflash_rows)
    return 0


def dataflash(trees: dict[str, Path], work: Path, n: int) -> None:
    """``soakcal import --format dataflash`` of an ``n``-message IMU log (1 kHz, ArduPilot
    4.x layout, written by the importer tests' own writer) before and after."""
    sys.path.insert(0, str(ROOT))
    from tests.calibration.log_writers import warmup_samples, write_dataflash

    log = work / f"log_{n}.bin"
    if not log.exists():
        write_dataflash(log, *warmup_samples(n=n, rate_hz=1000.0))
    outputs = {}
    print("| messages | command | code | wall s | CPU s | peak RSS MB | exit |")
    print("|---|---|---|---|---|---|---|")
    for name, code in trees.items():
        rec = work / f"rec_df_{n}_{name}.csv"
        r = timed(code, ["import", "--format", "dataflash", str(log), "-o", str(rec)], work)
        print(f"| {n:,} | import --format dataflash | {name} | {r['wall_s']:.1f} | "
              f"{r['cpu_s']:.1f} | {r['peak_mb']:.0f} | {r['rc']} |", flush=True)
        outputs[name] = (hashlib.sha256(rec.read_bytes()).hexdigest(),
                         str(r["stdout"]).replace(rec.name, "REC"))
    print(f"\n{n:,} DataFlash messages: recording and summary identical before/after: "
          f"{outputs['before'] == outputs['after']}")


if __name__ == "__main__":
    raise SystemExit(main())
