"""Fit speed: our SFEM fits next to a plain ``scipy.optimize.least_squares`` loop, same run.

    .venv/bin/python benchmarks/bench_speed.py [--campaigns 10000] [--steps 11]
                                               [--scipy-sample 2000] [--full]

Rows:

1. one 12-parameter reference fit, 24 positions (seed Table 1);
2. one reference fit, 1296 positions (seed §4.2 sphere);
3. a whole 11-step campaign (simulated, Table 1 at each step): per-step fits, and
   ``calibration.thermal.fit_campaign`` (per_step and joint) when that module exists;
4. throughput: ``campaigns × steps`` single-temperature 24-position reference fits
   on 2 worker processes (``multiprocessing``): :func:`fit_reference_batch`, a loop
   of :func:`fit_reference`, and the plain scipy loop.

"Plain scipy" = ``least_squares(residual, identity start, jac="2-point")`` with the
default TRF method: numeric Jacobian, no closed-form start. The single-fit and
scipy loops are timed on ``--scipy-sample`` problems and extrapolated (marked
``~``) unless ``--full``. The batch result is checked against the single fits.
"""

from __future__ import annotations

import argparse
import importlib
import multiprocessing as mp
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.batch_fit import fit_reference_batch  # noqa: E402
from calibration import fit, schedules, sfem  # noqa: E402
from simulators.campaign_sim import simulate_campaign, simulate_static_run  # noqa: E402
from simulators.truth import SensorTruth  # noqa: E402

WORKERS = 2


# --- problems -----------------------------------------------------------------
def make_problems(k: int, seed: int, refs: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """k single-temperature problems: raw, ref, sigma (k,N,3), ADXL355-like errors."""
    rng = np.random.default_rng(seed)
    ref1 = schedules.table1() if refs is None else refs
    n = ref1.shape[0]
    P = np.tile(sfem.identity_vector(), (k, 1))
    P[:, sfem.BIAS] = rng.uniform(-25e-3, 25e-3, (k, 3))
    P[:, sfem.SCALE] += rng.normal(0, 0.01, (k, 3))
    P[:, sfem.ALPHA] = rng.normal(0, 4e-3, (k, 3))
    P[:, sfem.MISALIGN] = rng.normal(0, 5e-3, (k, 3))
    ref = np.broadcast_to(ref1, (k, n, 3)).copy()
    sd_mean = 25e-6 * np.sqrt(62.5 / 2) / np.sqrt(200)  # ADXL355, 200 samples per mean
    raw = sfem.inverse(P[:, None, :], ref)  # each problem's p for all its n rows
    raw += rng.normal(0, sd_mean, raw.shape)
    sigma = np.full_like(raw, sd_mean)
    return raw, ref, sigma


def plain_scipy_fit(raw: np.ndarray, ref: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The baseline: TRF, finite-difference Jacobian, identity start."""

    def residual(p: np.ndarray) -> np.ndarray:
        return (((raw - p[sfem.BIAS]) @ sfem.matrix_from_vector(p).T - ref) / sigma).ravel()

    return least_squares(residual, sfem.identity_vector(), jac="2-point").x


# --- timing helpers -------------------------------------------------------------
def best_time(fn: Callable[[], object], repeats: int) -> float:
    """Best wall time of ``repeats`` calls (s): the least disturbed run."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _chunk_job(job: tuple[str, int, int]) -> tuple[float, np.ndarray]:
    """Worker: make chunk ``seed`` of ``k`` problems, fit them with ``kind``; (fit s, params)."""
    kind, k, seed = job
    raw, ref, sig = make_problems(k, seed)
    t0 = time.perf_counter()
    if kind == "batch":
        P = fit_reference_batch(raw, ref, sig).params
    elif kind == "single":
        P = np.array([fit.fit_reference(raw[i], ref[i], sig[i]).params.to_vector()
                      for i in range(k)])
    else:
        P = np.array([plain_scipy_fit(raw[i], ref[i], sig[i]) for i in range(k)])
    return time.perf_counter() - t0, P


def throughput(kind: str, total: int, chunk: int, pool: mp.pool.Pool) -> tuple[float, np.ndarray]:
    """Wall time (s) for ``total`` problems in chunks on the pool, and all parameters."""
    jobs = [(kind, min(chunk, total - s), 1000 + s // chunk) for s in range(0, total, chunk)]
    t0 = time.perf_counter()
    out = pool.map(_chunk_job, jobs)
    wall = time.perf_counter() - t0
    return wall, np.concatenate([p for _, p in out])


# --- benchmark -------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=10_000)
    ap.add_argument("--steps", type=int, default=11)
    ap.add_argument("--scipy-sample", type=int, default=2_000,
                    help="problems timed for the single-fit and scipy loops (then scaled)")
    ap.add_argument("--full", action="store_true", help="time every loop on all problems")
    args = ap.parse_args(argv)
    rows: list[tuple[str, str, str, str]] = []

    truth = SensorTruth.adxl355_typical(3)
    for label, sched, reps in (("24-position reference fit", schedules.table1(), 50),
                               ("1296-position reference fit", schedules.sphere(1296), 5)):
        rec = simulate_static_run(truth, sched, 25.0, seed=1).recording
        raw, ref, sig = rec.raw_g, rec.ref_g, rec.sigma_g
        ours = best_time(lambda: fit.fit_reference(raw, ref, sig), reps)  # noqa: B023
        base = best_time(lambda: plain_scipy_fit(raw, ref, sig), max(reps // 5, 1))  # noqa: B023
        batch = best_time(lambda: fit_reference_batch(raw[None], ref[None], sig[None]), reps)  # noqa: B023
        rows.append((label, f"{ours * 1e3:.2f} ms", f"{base * 1e3:.1f} ms",
                     f"{base / ours:.0f}x  (batch path, K=1: {batch * 1e3:.2f} ms)"))

    campaign = simulate_campaign(truth, seed=2)
    steps = campaign.steps()

    def per_step() -> None:
        for s in np.unique(steps):
            m = steps == s
            fit.fit_reference(campaign.raw_g[m], campaign.ref_g[m], campaign.sigma_g[m])

    def per_step_scipy() -> None:
        for s in np.unique(steps):
            m = steps == s
            plain_scipy_fit(campaign.raw_g[m], campaign.ref_g[m], campaign.sigma_g[m])

    ours = best_time(per_step, 10)
    base = best_time(per_step_scipy, 2)
    n_steps = len(np.unique(steps))
    rows.append((f"{n_steps}-step campaign, per-step fits", f"{ours * 1e3:.1f} ms",
                 f"{base * 1e3:.0f} ms", f"{base / ours:.0f}x"))
    try:
        thermal = importlib.import_module("calibration.thermal")
    except ImportError:
        thermal = None
    if thermal is not None and hasattr(thermal, "fit_campaign"):
        for method in getattr(thermal, "METHODS", ("per_step",)):
            t = best_time(lambda m=method: thermal.fit_campaign(campaign, method=m), 3)
            rows.append((f"{n_steps}-step campaign, thermal.fit_campaign({method})",
                         f"{t * 1e3:.0f} ms", "-", "-"))
    else:
        rows.append(("campaign thermal fit", "n/a", "-", "calibration.thermal.fit_campaign "
                     "not present"))

    total = args.campaigns * args.steps
    sample = total if args.full else min(args.scipy_sample, total)
    chunk_batch = 2_000
    with mp.get_context("fork").Pool(WORKERS) as pool:
        pool.map(_chunk_job, [("batch", 10, 0)] * WORKERS)  # warm the workers
        t_batch, _ = throughput("batch", total, chunk_batch, pool)
        t_single, _ = throughput("single", sample, max(sample // (4 * WORKERS), 1), pool)
        t_scipy, _ = throughput("scipy", sample, max(sample // (4 * WORKERS), 1), pool)
    scale = total / sample
    mark = "" if sample == total else "~"
    label = f"{args.campaigns} campaigns × {args.steps} steps = {total} fits, {WORKERS} workers"
    rows.append((label + " [batch]", f"{t_batch:.2f} s ({total / t_batch:,.0f}/s)",
                 f"{mark}{t_scipy * scale:.0f} s ({sample / t_scipy:,.0f}/s)",
                 f"{t_scipy * scale / t_batch:.0f}x"))
    rows.append((label + " [fit_reference loop]",
                 f"{mark}{t_single * scale:.1f} s ({sample / t_single:,.0f}/s)",
                 f"{mark}{t_scipy * scale:.0f} s", f"{t_scipy / t_single:.0f}x"))

    # Agreement: batch vs single vs scipy on the same problems.
    raw, ref, sig = make_problems(200, 7)
    Pb = fit_reference_batch(raw, ref, sig).params
    Ps = np.array([fit.fit_reference(raw[i], ref[i], sig[i]).params.to_vector()
                   for i in range(200)])
    Pq = np.array([plain_scipy_fit(raw[i], ref[i], sig[i]) for i in range(200)])

    w = max(len(r[0]) for r in rows)
    print(f"{'case':{w}s}  {'ours':>24s}  {'plain scipy':>22s}  speed-up")
    print("-" * (w + 62))
    for r in rows:
        print(f"{r[0]:{w}s}  {r[1]:>24s}  {r[2]:>22s}  {r[3]}")
    print()
    print(f"agreement on 200 problems: max |batch − fit_reference| = "
          f"{np.abs(Pb - Ps).max():.1e}, max |fit_reference − plain scipy| = "
          f"{np.abs(Ps - Pq).max():.1e} (parameter units)")
    load = os.getloadavg()
    print(f"machine: {mp.cpu_count()} CPUs, numpy {np.__version__}, load average "
          f"{load[0]:.1f}/{load[1]:.1f} (1/5 min: figures are only comparable when it is "
          f"below the CPU count); '~' = timed on {sample} problems and scaled to {total}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
