"""Firmware export accuracy: the C header (double and float) against Python ``compensate``.

    .venv/bin/python benchmarks/bench_export.py [--sensors 5] [--readings 100000]

For each simulated ADXL355 (``SensorTruth.adxl355_typical(seed)``): calibrate a
simulated −40…60 °C campaign (``fit_campaign``, defaults), export the model with
``soakcal export --format c``, compile a driver with the system C compiler
(``cc -std=c99 -O2 -lm``), feed it ``--readings`` random readings (directions
uniform on the sphere, |raw| 0.5–1.5 g, temperatures uniform over the valid
range) and compare with :meth:`ThermalModel.compensate` (what ``soakcal
compensate`` computes). Prints the largest per-axis difference of the double
and the float function (µg) and the C throughput of each (readings/s).
Requirement: double < 0.1 µg; float below the bound the header states
(``calibration.export.FLOAT_BOUND_UG``).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from calibration.export import FLOAT_BOUND_UG, export_c_header  # noqa: E402
from calibration.thermal import fit_campaign  # noqa: E402
from simulators.campaign_sim import simulate_campaign  # noqa: E402
from simulators.truth import SensorTruth  # noqa: E402

DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "soakcal_cal.h"
int main(int argc, char **argv) {
    long n = atol(argv[1]), i;
    double *in = malloc(sizeof(double) * 4 * n), *od = malloc(sizeof(double) * 3 * n);
    float *of = malloc(sizeof(float) * 3 * n);
    struct timespec t0, t1, t2;
    if (fread(in, sizeof(double), 4 * n, stdin) != (size_t)(4 * n)) return 3;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (i = 0; i < n; ++i) soakcal_compensate(in + 4 * i, in[4 * i + 3], od + 3 * i);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    for (i = 0; i < n; ++i) {
        float r[3] = {(float)in[4 * i], (float)in[4 * i + 1], (float)in[4 * i + 2]};
        soakcal_compensate_f(r, (float)in[4 * i + 3], of + 3 * i);
    }
    clock_gettime(CLOCK_MONOTONIC, &t2);
    fwrite(od, sizeof(double), 3 * n, stdout);
    for (i = 0; i < 3 * n; ++i) { double v = of[i]; fwrite(&v, sizeof(double), 1, stdout); }
    fprintf(stderr, "%.9f %.9f\n", (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec),
            (t2.tv_sec - t1.tv_sec) + 1e-9 * (t2.tv_nsec - t1.tv_nsec));
    return 0;
}
"""


def one_sensor(seed: int, readings: int, cc: str, work: Path) -> dict[str, float]:
    truth = SensorTruth.adxl355_typical(seed)
    rec = simulate_campaign(truth, tuple(float(v) for v in range(-40, 61, 10)), seed=seed + 1000)
    model = fit_campaign(rec).model
    (work / "soakcal_cal.h").write_text(export_c_header(model, source_name=f"sensor{seed}"))
    (work / "driver.c").write_text(DRIVER)
    exe = work / "driver"
    subprocess.run([cc, "-std=c99", "-O2", "-I", str(work), str(work / "driver.c"), "-o",
                    str(exe), "-lm"], check=True)
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(readings, 3))
    raw = v / np.linalg.norm(v, axis=1, keepdims=True) * rng.uniform(0.5, 1.5, (readings, 1))
    lo, hi = model.valid_c  # type: ignore[misc]
    temp = rng.uniform(lo, hi, readings)
    data = np.column_stack([raw, temp]).astype("<f8").tobytes()
    proc = subprocess.run([str(exe), str(readings)], input=data, capture_output=True, check=True)
    out = np.frombuffer(proc.stdout, "<f8").reshape(2, readings, 3)
    t_d, t_f = (float(x) for x in proc.stderr.split())
    expected = model.compensate(raw, temp)
    return {
        "double_ug": float(np.abs(out[0] - expected).max() * 1e6),
        "float_ug": float(np.abs(out[1] - expected).max() * 1e6),
        "double_per_s": readings / t_d,
        "float_per_s": readings / t_f,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensors", type=int, default=5)
    ap.add_argument("--readings", type=int, default=100_000)
    a = ap.parse_args(argv)
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        print("no C compiler on PATH (cc, gcc, clang)", file=sys.stderr)
        return 2
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for s in range(a.sensors):
            r = one_sensor(s, a.readings, cc, Path(d))
            rows.append(r)
            print(f"sensor {s}: max |C - Python| double {r['double_ug']:.2e} µg, float "
                  f"{r['float_ug']:.3f} µg; {r['double_per_s'] / 1e6:.1f} M/s double, "
                  f"{r['float_per_s'] / 1e6:.1f} M/s float")
    worst_d = max(r["double_ug"] for r in rows)
    worst_f = max(r["float_ug"] for r in rows)
    ok = worst_d < 0.1 and worst_f < FLOAT_BOUND_UG
    print(f"worst over {a.sensors} sensors x {a.readings} readings: double {worst_d:.2e} µg "
          f"(< 0.1), float {worst_f:.3f} µg (< {FLOAT_BOUND_UG:g}): {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
