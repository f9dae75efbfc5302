"""Real recordings from other labs: import → norm-mode SFEM fit → RMSE, leave-one-out, noise floor.

    .venv/bin/python benchmarks/bench_realdata.py [--realdata /work/shared/realdata]

For each dataset in ``/work/shared/realdata`` (README there): the ``soakcal import``
path with its default detector settings, then the seed's SFEM in norm mode (9
identifiable parameters b, S, C; the rotation M is invisible to |g|), twice:

* ``equal``: every interval weighs the same (what imu_tk / the reference figures do);
* ``sd/√n``: weights from the recorded noise of each mean (what ``calibrate`` does
  when ``sd_*`` and ``n`` are present).

Columns: |g| RMSE before (nominal scale) and after, in mg; leave-one-interval-out
(LOO: refit without interval i, predict its |g| error; RMS over i); the noise floor
of one interval's |g| (sd/√n projected on the gravity direction; median over
intervals). Ferraris has only 6 positions: norm mode is rank-deficient there, so its
row is a reference-mode fit with the section labels (±x, ±y, ±z) as references.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a plain script from a checkout
    sys.path.insert(0, str(ROOT))

from calibration import importers  # noqa: E402
from calibration.errors import NotIdentifiable  # noqa: E402
from calibration.fit import FitResult, fit_norm, fit_reference  # noqa: E402
from calibration.recording import Recording  # noqa: E402

DATASETS: tuple[tuple[str, str, str, dict[str, object]], ...] = (
    ("openaxes-adxl355", "openaxes", "openaxes-adxl355/log_imu9_2022-06-22_22-13-55.csv", {}),
    ("openaxes-bmi160", "openaxes", "openaxes-adxl355/log_imu9_2022-06-22_22-13-55.csv",
     {"sensor": "bmi160"}),
    ("imu_tk-xsens", "imu_tk", "imu_tk-xsens/xsens_acc.mat", {}),
    ("tomisuarez2-mpu6050", "mpu6050", "tomisuarez2-mpu6050/example_data_calibration.csv", {}),
    ("imucal-ferraris (session)", "ferraris", "imucal-ferraris/example_ferraris_session.csv", {}),
    ("imucal-ferraris (annotated)", "ferraris", "imucal-ferraris/annotated_session.csv", {}),
)
# The README's imu_tk-style 9-parameter figures (mg): before, after, LOO.
REFERENCE_MG: dict[str, tuple[float, float, float]] = {
    "openaxes-adxl355": (36.0, 0.28, 0.39),
    "openaxes-bmi160": (float("nan"), 0.82, 1.05),
    "imu_tk-xsens": (5.7, 0.10, 0.16),
    "tomisuarez2-mpu6050": (71.0, 0.05, 1.07),
}


@dataclass
class Row:
    name: str
    mode: str
    weights: str
    n_intervals: int
    before_mg: float
    after_mg: float
    loo_mg: float | None
    loo_note: str
    floor_mg: float
    seconds: float


def loo_rmse_mg(
    raw_g: np.ndarray, sigma_g: np.ndarray | None, fit: Callable[..., FitResult],
    ref_g: np.ndarray | None = None,
) -> float:
    """Leave-one-interval-out: refit without i, |g| error of interval i; RMS over i, mg."""
    err = []
    for i in range(raw_g.shape[0]):
        keep = np.arange(raw_g.shape[0]) != i
        sig = None if sigma_g is None else sigma_g[keep]
        res = fit(raw_g[keep], sig) if ref_g is None else fit(raw_g[keep], ref_g[keep], sig)
        err.append(float(np.linalg.norm(res.params.apply(raw_g[i : i + 1])[0]) - res.g_local))
    return float(np.sqrt(np.mean(np.square(err))) * 1e3)


def noise_floor_mg(rec: Recording) -> float:
    """Median over intervals of σ(|mean|) = ‖u ∘ sd/√n‖, u the gravity direction, mg."""
    sig = rec.sigma_g
    u = rec.raw_g / np.linalg.norm(rec.raw_g, axis=1, keepdims=True)
    return float(np.median(np.sqrt(np.sum((u * sig) ** 2, axis=1))) * 1e3)


def run_dataset(name: str, fmt: str, path: Path, options: dict[str, object]) -> list[Row]:
    t0 = time.perf_counter()
    _, intervals, rec = importers.import_static(fmt, path, **options)
    t_import = time.perf_counter() - t0
    raw, floor = rec.raw_g, noise_floor_mg(rec)
    rows: list[Row] = []
    for label, sig in (("equal", None), ("sd/√n", rec.sigma_g)):
        t1 = time.perf_counter()
        try:
            res = fit_norm(raw, sig)
            mode, ref = "norm", None
        except NotIdentifiable:
            if rec.ref_g is None:
                raise
            res = fit_reference(raw, rec.ref_g, sig)
            mode, ref = "reference", rec.ref_g
        try:
            fitter = fit_norm if ref is None else fit_reference
            loo, note = loo_rmse_mg(raw, sig, fitter, ref), ""
        except NotIdentifiable as exc:
            loo, note = None, str(exc)
        rows.append(Row(name, mode, label, len(intervals), res.rmse_norm_before_ug / 1e3,
                        res.rmse_norm_ug / 1e3, loo, note, floor,
                        t_import + time.perf_counter() - t1))
    return rows


def format_table(rows: list[Row]) -> str:
    head = (f"{'dataset':28s} {'mode':9s} {'weights':7s} {'N':>3s} {'before':>8s} "
            f"{'after':>7s} {'LOO':>7s} {'floor':>6s} {'after/floor':>11s} "
            f"{'ref after':>9s} {'ref LOO':>7s} {'s':>5s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        ref = REFERENCE_MG.get(r.name, (np.nan, np.nan, np.nan))
        loo = f"{r.loo_mg:7.3f}" if r.loo_mg is not None else f"{'n/a':>7s}"
        lines.append(
            f"{r.name:28s} {r.mode:9s} {r.weights:7s} {r.n_intervals:3d} {r.before_mg:8.2f} "
            f"{r.after_mg:7.3f} {loo} {r.floor_mg:6.3f} {r.after_mg / r.floor_mg:11.1f} "
            f"{ref[1]:9.2f} {ref[2]:7.2f} {r.seconds:5.2f}")
    notes = sorted({f"{r.name}: LOO n/a: {r.loo_note}" for r in rows if r.loo_mg is None})
    lines += ["", "all figures in mg of |g|; before = nominal scale; floor = median sd/√n of "
              "one interval's |g|"] + notes
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default="/work/shared/realdata", type=Path)
    args = ap.parse_args(argv)
    if not args.realdata.is_dir():
        print(f"no real data at {args.realdata}", file=sys.stderr)
        return 2
    rows: list[Row] = []
    for name, fmt, rel, options in DATASETS:
        path = args.realdata / rel
        if not path.exists():
            print(f"skip {name}: {path} missing", file=sys.stderr)
            continue
        rows += run_dataset(name, fmt, path, options)
    print(format_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
