"""Warm-ups of 2-5 orientations: absolute parameters against the truth and the full fit.

Two parts (calibration/warmup_absolute.py):

* **twin**: a full-SFEM ADXL355-class sensor (simulators/truth.py, a fresh draw per
  seed) warming -10 -> +10 °C over 10 min while a hand turns it between faces every
  20 s, 50 Hz raw samples, 1 mg noise per sample. For each face set, through
  ``calibration.fitting.fit``: which parameters are fitted absolutely, the share of
  them within 1, 2 and 3 stated standard errors of the truth at centre_c, the median
  stated error, and the fit's time.
* **real**: the shared multi-position recordings (no temperature channel): each static
  interval cut into 1-s block means; the whole recording's 9-parameter norm-mode fit
  (calibration.fit.fit_norm on the interval means) is the reference. Subsets of 2-5
  intervals (the most opposite pair, then the intervals closest to the remaining
  faces) go through the warm-up's absolute part at degree 0 (``absolute_part``); each
  determined parameter is compared with the full fit: |difference| / the subset's
  stated error.

* **turned once**: z up while cold, z down while warm (200 s at 50 Hz, 12 seeds): the error
  of the z bias change, with the log started 0-2.5 s later.

Run: ``.venv/bin/python -m benchmarks.bench_warmup_orientations [--seeds N] [--realdata DIR]``
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from calibration import importers, sfem
from calibration.fit import fit_norm
from calibration.fitting import fit
from calibration.gate import distinct_orientations
from calibration.recording import Recording
from calibration.warmup_absolute import absolute_part
from simulators.truth import SensorTruth
from simulators.warmup_log import cycled, warmup_log

FACES = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0)]
SETS = {"norm": (2, 3, 4, 5), "reference": (2, 3, 4)}
REAL = (("imu_tk-xsens", "imu_tk", "imu_tk-xsens/xsens_acc.mat", {}),
        ("openaxes-adxl355", "openaxes", "openaxes-adxl355/log_imu9_2022-06-22_22-13-55.csv",
         {}),
        ("tomisuarez2-mpu6050", "mpu6050", "tomisuarez2-mpu6050/example_data_calibration.csv",
         {}))
BLOCK_S = 1.0


def twin(seeds: int) -> list[str]:
    lines = ["| mode | faces | fitted absolutely | within 1σ / 2σ / 3σ | median σ: b (µg), "
             "s (ppm), m (µrad) | fit, s |", "|---|---|---|---|---|---|"]
    for mode, counts in SETS.items():
        for k in counts:
            z: list[float] = []
            sig: dict[str, list[float]] = {"g": [], "1": [], "rad": []}
            names: set[str] = set()
            secs = []
            for seed in range(seeds):
                sensor = SensorTruth.adxl355_typical(seed=seed)
                rec, _ = warmup_log(seconds=600.0, rate_hz=50.0, t_start_c=-10.0,
                                    t_end_c=10.0, tau_s=200.0,
                                    segments=cycled(FACES[:k], 600.0, 20.0), sensor=sensor,
                                    seed=seed, reference=mode == "reference")
                t0 = time.perf_counter()
                result = fit(rec)
                secs.append(time.perf_counter() - t0)
                truth = sensor.params_vector_at(result.model.t_centre_c - sensor.temp_offset_c)
                for n, p in result.report["absolute"]["parameters"].items():
                    i = sfem.PARAM_NAMES.index(n)
                    z.append(abs(p["value"] - truth[i]) / p["stderr"])
                    sig[p["unit"]].append(p["stderr"])
                    names.add(n)
            za = np.asarray(z)
            shown = [f"{np.median(sig[u]) * 1e6:.0f}" if sig[u] else "-"
                     for u in ("g", "1", "rad")]
            lines.append(
                f"| {mode} | {k} ({', '.join(_face(f) for f in FACES[:k])}) | "
                f"{', '.join(n for n in sfem.PARAM_NAMES if n in names)} | "
                f"{np.mean(za < 1):.0%} / {np.mean(za < 2):.0%} / {np.mean(za < 3):.0%} "
                f"(n={za.size}, max {za.max():.1f}σ) | {' / '.join(shown)} | "
                f"{np.median(secs):.2f} |")
    return lines


def turned_once(seeds: int) -> list[str]:
    """A board turned over once (z up while cold, z down while warm): RMS error (µg) of the
    z bias change over the middle 80 % of the valid range, the log started 0-2.5 s later
    (where the 5-s captures fall)."""
    lines = ["| log starts at | x | y | z (max) |", "|---|---|---|---|"]
    for start_s in (0.0, 0.5, 1.0, 2.5):
        errs = []
        for seed in range(seeds):
            rec, truth = warmup_log(seconds=200, rate_hz=50, seed=seed,
                                    segments=[(100.0, (0, 0, -1))])
            model = fit(rec.subset(rec.t_s >= start_s)).model
            lo, hi = model.valid_c
            a, b = lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)
            change = model.params_vector_at(b)[:3] - model.params_vector_at(a)[:3]
            true_change = (truth.bias_g(np.array([b])) - truth.bias_g(np.array([a])))[0]
            errs.append((change - true_change) * 1e6)
        e = np.array(errs)
        rms = np.sqrt(np.mean(e ** 2, axis=0))
        lines.append(f"| {start_s:g} s | {rms[0]:.0f} | {rms[1]:.0f} | {rms[2]:.0f} "
                     f"({np.max(np.abs(e[:, 2])):.0f}) |")
    return lines


def _face(u: tuple[int, int, int]) -> str:
    k = int(np.argmax(np.abs(u)))
    return f"{'+-'[u[k] < 0]}{'xyz'[k]}"


def _blocks(raw: importers.RawImport, intervals: list[tuple[int, int]]
            ) -> tuple[np.ndarray, np.ndarray]:
    """1-s block means of each interval (N,3) and their interval index (N,)."""
    means, labels = [], []
    for j, (a, b) in enumerate(intervals):
        t, acc = raw.t_s[a:b], raw.acc_g[a:b]
        block = np.floor((t - t[0]) / BLOCK_S).astype(int)
        for q in np.unique(block):
            sel = block == q
            if sel.sum() >= 5:
                means.append(acc[sel].mean(axis=0))
                labels.append(j)
    return np.asarray(means), np.asarray(labels)


def _subsets(directions: np.ndarray) -> dict[int, list[int]]:
    """2-5 intervals: the most opposite pair, then the ones nearest the other faces."""
    cos = directions @ directions.T
    i, j = np.unravel_index(int(np.argmin(cos)), cos.shape)
    chosen = [int(i), int(j)]
    axis = int(np.argmax(np.abs(directions[i])))
    others = [np.eye(3)[a] * s for a in range(3) if a != axis for s in (1, -1)]
    out = {2: list(chosen)}
    for k, face in enumerate(others[:3], start=3):
        rest = [q for q in range(len(directions)) if q not in chosen]
        chosen.append(max(rest, key=lambda q: float(directions[q] @ face)))
        out[k] = list(chosen)
    return out


def real(root: Path) -> list[str]:
    lines = ["| recording | intervals | determined | |Δ| / σ (each) | within 2σ |",
             "|---|---|---|---|---|"]
    for name, fmt, rel, options in REAL:
        path = root / rel
        if not path.exists():
            lines.append(f"| {name} | (missing: {rel}) | | | |")
            continue
        raw, intervals, rec = importers.import_static(fmt, path, **options)
        full = fit_norm(rec.raw_g, rec.sigma_g)
        p_full, se_full = full.params.to_vector(), full.stderr
        means, labels = _blocks(raw, intervals)
        directions = rec.raw_g / np.linalg.norm(rec.raw_g, axis=1, keepdims=True)
        for k, subset in _subsets(directions).items():
            sel = np.isin(labels, subset)
            caps = Recording.from_columns({
                "t_s": np.arange(int(sel.sum()), dtype=float),
                "sensor_c": np.full(int(sel.sum()), 25.0),
                "ax": means[sel, 0], "ay": means[sel, 1], "az": means[sel, 2]})
            ori = distinct_orientations(caps.raw_g)
            x = np.zeros(len(caps))
            folds = np.arange(len(caps)) % 2
            ab = absolute_part(caps, ori, x, sfem.identity_vector()[:, None], 0, folds,
                               None, 1.0)
            shown, within = [], []
            for n, c, s in zip(ab.names, ab.coeffs[:, 0], ab.stderr[:, 0], strict=True):
                i = sfem.PARAM_NAMES.index(n)
                sigma = float(np.hypot(s, se_full[i] if np.isfinite(se_full[i]) else 0.0))
                z = abs(c - p_full[i]) / sigma
                unit = 1e3 if i < 3 else 1e6
                shown.append(f"{n} {(c - p_full[i]) * unit:+.3g}±{sigma * unit:.2g} "
                             f"({z:.1f}σ)")
                within.append(z < 2)
            for n, se in ab.loose.items():
                unit, u = (1e3, "mg") if n in sfem.PARAM_NAMES[:3] else (1e2, "%")
                shown.append(f"{n} held: ±{se * unit:.2g} {u}")
            lines.append(f"| {name} | {k} ({ori.count} found) | "
                         f"{', '.join(ab.names) or 'none'} | {'; '.join(shown) or '-'} | "
                         f"{sum(within)}/{len(within)} |")
    lines.append("")
    lines.append("Δ: subset − full fit, b in mg, s in ppm; σ: the subset's stated error and "
                 "the full fit's, in quadrature.")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--realdata", type=Path, default=Path(os.environ.get(
        "SOAKCAL_REALDATA", Path(__file__).resolve().parents[1] / "tests/data/realdata")))
    args = ap.parse_args(argv)
    print("== twin: absolute parameters against the truth at centre_c ==")
    print("\n".join(twin(args.seeds)))
    print("\n== turned over once: z bias change error, µg RMS over 12 seeds ==")
    print("\n".join(turned_once(12)))
    print("\n== real recordings: 2-5 intervals against the whole recording's fit ==")
    print("\n".join(real(args.realdata)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
