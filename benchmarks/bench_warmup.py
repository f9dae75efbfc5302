"""One-orientation warm-ups: calibrate's time on 100,000 raw rows and its held-out error.

The simulated log (simulators/warmup_log.py) is the issue's case: z up, raw samples at
500 Hz, the die warming -18.7 -> -13.3 °C, a 0.06 °C-quantised temperature channel,
1 mg noise per sample. Two figures:

* **time**: ``soakcal calibrate`` as a subprocess on the 100,000-row CSV (wall and CPU),
  and the in-process fit alone (read -> capture means -> gate -> warm-up fit).
* **held-out error**: 10-s blocks alternately fitted and held out; RMS about their
  mean of the held-out 5-s means of each axis, for: no compensation, a per-axis cubic
  of the raw samples against each sample's temperature (PX4's form, own
  implementation), and soakcal (calibrate on the fitted blocks, compensate the
  held-out ones). The noise floor is the RMS a perfect model would leave (noise of a
  5-s mean: 1 mg / sqrt(2500)).

Run: ``.venv/bin/python -m benchmarks.bench_warmup [--seeds N]``
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.captures import capture_means, capture_temperature_c
from calibration.gate import plan
from calibration.model_file import load_model
from calibration.recording import read_recording, write_recording
from calibration.warmup import fit_warmup
from simulators.warmup_log import warmup_log

BLOCK_S = 10.0
MEAN_S = 5.0


def _soakcal(*argv: str) -> tuple[float, float]:
    """Wall and CPU seconds of one ``soakcal`` run (children's rusage)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "service.cli", *argv], check=True,
                   capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _means_rms_mg(t_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(3,) RMS about their mean of the 5-s means of ``values`` (N,3), mg."""
    key = np.floor(t_s / MEAN_S).astype(int)
    _, inv = np.unique(key, return_inverse=True)
    means = np.stack([np.bincount(inv, weights=values[:, a]) / np.bincount(inv)
                      for a in range(3)], axis=1)
    return np.sqrt(np.mean((means - means.mean(axis=0)) ** 2, axis=0)) * 1e3


def heldout(seed: int, tmp: Path) -> dict[str, np.ndarray]:
    rec, _ = warmup_log(seed=seed)
    fit_rows = (np.floor(rec.t_s / BLOCK_S).astype(int) % 2) == 0
    held = ~fit_rows
    temp = rec.temperature_c()
    out: dict[str, np.ndarray] = {"none": _means_rms_mg(rec.t_s[held], rec.raw_g[held])}
    px4 = np.empty((int(held.sum()), 3))
    for a in range(3):
        c = np.polyfit(temp[fit_rows], rec.raw_g[fit_rows, a], 3)
        px4[:, a] = rec.raw_g[held, a] - np.polyval(c, temp[held])
    out["per-axis cubic (PX4 form)"] = _means_rms_mg(rec.t_s[held], px4)
    src, model = tmp / "fit.csv", tmp / "m.json"
    write_recording(src, rec.subset(fit_rows))
    _soakcal("calibrate", str(src), "-o", str(model))
    m = load_model(model)
    held_rec = rec.subset(held)
    held_temp = capture_temperature_c(held_rec, capture_means(held_rec))
    cal = m.compensate(held_rec.raw_g, held_temp, extrapolate=True)
    out["soakcal"] = _means_rms_mg(held_rec.t_s, cal)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rec, _ = warmup_log(seed=0)
        src = tmp / "warmup_100k.csv"
        write_recording(src, rec)
        wall, cpu = _soakcal("calibrate", str(src), "-o", str(tmp / "model.json"))
        t0 = time.perf_counter()
        r = read_recording(src)
        caps = capture_means(r)
        fit_warmup(caps.recording, plan(caps.recording).orientations)
        inproc = time.perf_counter() - t0
        print(f"calibrate on {len(rec)} raw rows: {wall:.2f} s wall, {cpu:.2f} s CPU "
              f"(subprocess, imports included); read + capture means + gate + fit "
              f"in process: {inproc:.2f} s")
        rows: dict[str, list[np.ndarray]] = {}
        for seed in range(args.seeds):
            for name, v in heldout(seed, tmp).items():
                rows.setdefault(name, []).append(v)
        floor = 1.0 / np.sqrt(MEAN_S * 500)
        print(f"held-out RMS of 5-s means, mg (x, y, z), mean over {args.seeds} seed(s); "
              f"noise floor {floor:.3f} mg")
        for name, vs in rows.items():
            v = np.mean(vs, axis=0)
            print(f"  {name:28s} " + "  ".join(f"{x:.4f}" for x in v))


if __name__ == "__main__":
    main()
