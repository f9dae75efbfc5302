"""Real recordings from other labs: import → norm-mode SFEM fit → RMSE, leave-one-out, noise floor.

    .venv/bin/python benchmarks/bench_realdata.py [--realdata DIR]

``DIR`` defaults to ``$SOAKCAL_REALDATA``, else the vendored ``tests/data/realdata`` (which
lacks the OpenAXES log: its data licence is not stated, so that dataset is skipped there).
For each dataset in that folder (each with its README): the ``soakcal import``
path with its default detector settings, then the seed's SFEM in norm mode (9
identifiable parameters b, S, C; the rotation M is invisible to |g|), three times:

* ``equal``: every interval weighs the same (what imu_tk / the reference figures do);
* ``sd/√n``: weights from the recorded noise of each mean alone (``model_floor=None``);
* ``+floor``: sd/√n with the model-error floor chosen from the residual excess (what
  ``calibrate`` does when ``sd_*`` and ``n`` are present; docs/fit-honesty.md).

Columns: |g| RMSE before (nominal scale) and after, in mg; leave-one-interval-out
(LOO: refit without interval i, predict its |g| error; RMS over i); the noise floor
of one interval's |g| (sd/√n projected on the gravity direction; median over
intervals). Ferraris has only 6 positions: norm mode is rank-deficient there, so its
row is a reference-mode fit with the section labels (±x, ±y, ±z) as references.

Three more tables (issue 11 / issue 9 / issue 20):

* **soakcal defaults vs peers** -- exactly what ``soakcal import`` (detector threshold
  and trim chosen by leave-one-interval-out, :mod:`calibration.static_choice`) and
  ``soakcal calibrate`` (sd/√n weights with the model-error floor, hand-placed labels
  as a prior; ``loo_rmse_ug`` of :mod:`calibration.holdout`) report, next to the
  peer tools' figures quoted in issue 11 and the realdata README;
* **hand-placed Ferraris** -- |g| error on the six labelled positions and on the
  seven other static periods of the same session (found by the default detector
  outside the labelled sections; never used by the fit), labels exact vs
  hand-placed, next to imucal's figures quoted in issue 9;
* **imu_tk's method on the same intervals** -- imu_tk's accelerometer calibration
  (Pretto/Tedaldi: static detector with a 101-sample window and a threshold of
  ``th_mult`` × the variance norm of the first 3000 samples, ``th_mult`` 2…10, intervals
  of ≥ 100 samples; 9 parameters, upper-triangular misalignment, |g| residual with
  equal weights; per sample over each interval's first 100 samples, its default, or on
  interval means, its ``acc_use_means``), re-implemented here from its description,
  next to ``soakcal calibrate``'s leave-one-out on *those same intervals*. Every
  column predicts the same held-out target, the interval's mean; only the fit differs.
  (``--peers-only`` prints just this table.)

``--layouts`` (issue 20: what a person reads, whatever layout the rows come in): each
recording written three ways -- one row per static interval (``soakcal import``), every
raw sample (``--raw``), 1-s block means (``--block-s 1``, blocks not checked for
stillness) -- then ``soakcal calibrate --json`` and ``soakcal diagnose --json`` on each,
as subprocesses: exit status, what was fitted, the held-out figure, or the refusal;
diagnose's verdict. Only that table is printed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a plain script from a checkout
    sys.path.insert(0, str(ROOT))

from scipy.optimize import least_squares  # noqa: E402

from calibration import holdout, importers, static_choice  # noqa: E402
from calibration.errors import NotIdentifiable  # noqa: E402
from calibration.fit import FitResult, fit_norm, fit_reference  # noqa: E402
from calibration.recording import Recording  # noqa: E402
from calibration.thermal import fit_campaign  # noqa: E402

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
    for label, sig, floor_rule in (("equal", None, None), ("sd/√n", rec.sigma_g, None),
                                   ("+floor", rec.sigma_g, "auto")):
        t1 = time.perf_counter()
        norm = partial(fit_norm, model_floor=floor_rule)
        refit = partial(fit_reference, model_floor=floor_rule)
        try:
            res = norm(raw, sig)
            mode, ref = "norm", None
        except NotIdentifiable:
            if rec.ref_g is None:
                raise
            res = refit(raw, rec.ref_g, sig)
            mode, ref = "reference", rec.ref_g
        try:
            fitter = norm if ref is None else refit
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


# Peer figures (mg): (tool, fit, leave-one-out). Issue 11 for imu_tk on its own data and
# on the BMI160 channel; the realdata README's imu_tk-style 9-parameter fit otherwise.
PEERS_MG: dict[str, tuple[str, float, float]] = {
    "openaxes-adxl355": ("imu_tk-style (README)", 0.28, 0.39),
    "openaxes-bmi160": ("imu_tk (issue 11)", 0.82, 1.052),
    "imu_tk-xsens": ("imu_tk (issue 11)", 0.099, 0.135),
    "tomisuarez2-mpu6050": ("imu_tk-style (README)", 0.05, 1.07),
}
# imucal's Ferraris method on the session (issue 9): |g| error on the six positions
# and on the other static periods, mg.
IMUCAL_FERRARIS_MG = (0.04, 0.5)


@dataclass
class DefaultsRow:
    name: str
    n_intervals: int
    detector: str
    fit_mg: float | None
    loo_mg: float | None
    warnings: list[str]


def run_defaults(name: str, fmt: str, path: Path, options: dict[str, object]) -> DefaultsRow:
    """The ``soakcal import`` + ``soakcal calibrate --json`` path with no flags."""
    raw = importers.read_source(fmt, path, **options)
    choice = static_choice.choose_detector(raw, importers.DEFAULT_DETECTOR[fmt])
    rec = importers.intervals_to_recording(raw, choice.intervals, path=str(path))
    held = holdout.leave_one_out(rec, fit_campaign(rec))
    st = choice.settings
    det = f"{st.threshold:g}x/{st.trim_s:g}s ({choice.chosen_by})"
    return DefaultsRow(name, len(rec), det, _mg(held["rmse_ug"]), _mg(held["loo_rmse_ug"]),
                       held["warnings"])


def _mg(ug: float | None) -> float | None:
    return None if ug is None else ug / 1e3


def format_defaults(rows: list[DefaultsRow]) -> str:
    head = (f"{'dataset':28s} {'N':>3s} {'detector':26s} {'fit':>7s} {'LOO':>7s} "
            f"{'peer':22s} {'p.fit':>6s} {'p.LOO':>6s}  LOO vs best peer")
    lines = [head, "-" * len(head)]
    for r in rows:
        peer = PEERS_MG.get(r.name)
        if peer is None:
            continue
        fit = f"{r.fit_mg:7.3f}" if r.fit_mg is not None else f"{'n/a':>7s}"
        loo = f"{r.loo_mg:7.3f}" if r.loo_mg is not None else f"{'null':>7s}"
        if r.loo_mg is None:
            verdict = "no figure: too few spare degrees of freedom (warned)"
        else:
            verdict = "no worse" if r.loo_mg <= peer[2] else "WORSE"
        lines.append(f"{r.name:28s} {r.n_intervals:3d} {r.detector:26s} {fit} {loo} "
                     f"{peer[0]:22s} {peer[1]:6.3f} {peer[2]:6.3f}  {verdict}")
    return "\n".join(lines)


def other_static_periods(raw: importers.RawImport) -> np.ndarray:
    """Means (g) of the static periods the default detector finds outside the sections."""
    st = importers.DEFAULT_DETECTOR["ferraris"]
    found = importers.detect_static_intervals(
        raw.t_s, raw.acc_g, window_s=st.window_s, threshold=st.threshold,
        min_duration_s=st.min_duration_s, trim_s=st.trim_s)
    secs = raw.sections or []
    other = [(s, e) for s, e in found if all(e <= a or s >= b for a, b in secs)]
    return np.array([raw.acc_g[s:e].mean(axis=0) for s, e in other]).reshape(-1, 3)


def run_ferraris(path: Path) -> list[str]:
    """|g| error (mg) on the six hand-placed positions and on the session's other rests."""
    raw = importers.read_source("ferraris", path)
    rec = importers.intervals_to_recording(raw, importers.find_intervals(
        raw, importers.DEFAULT_DETECTOR["ferraris"]), path=str(path))
    other = other_static_periods(raw)

    def g_mg(res: FitResult, x: np.ndarray) -> float:
        if x.size == 0:
            return float("nan")
        return float(np.sqrt(np.mean((np.linalg.norm(res.params.apply(x), axis=1)
                                      - res.g_local) ** 2)) * 1e3)

    exact = fit_reference(rec.raw_g, rec.ref_g, rec.sigma_g)
    tol = np.radians(rec.columns["ref_tol_deg"])
    hand = fit_reference(rec.raw_g, rec.ref_g, rec.sigma_g, ref_tol_rad=tol)
    lines = [f"{path.name}: {len(rec)} labelled positions, {len(other)} other static "
             "periods (held out: never seen by the fit)",
             f"  {'fit':46s} {'six':>8s} {'other':>8s}",
             f"  {'labels exact (before issue 9)':46s} {g_mg(exact, rec.raw_g):8.4f} "
             f"{g_mg(exact, other):8.4f}",
             f"  {'labels hand-placed, ref_tol_deg = 2 (default)':46s} "
             f"{g_mg(hand, rec.raw_g):8.4f} {g_mg(hand, other):8.4f}"]
    if "ferraris_session" in path.name:
        lines.append(f"  {'imucal Ferraris (issue 9)':46s} {IMUCAL_FERRARIS_MG[0]:8.4f} "
                     f"{IMUCAL_FERRARIS_MG[1]:8.4f}")
    for deg in (0.1, 0.5, 1.0, 5.0):
        r = fit_reference(rec.raw_g, rec.ref_g, rec.sigma_g, ref_tol_rad=np.radians(deg))
        lines.append(f"  {f'  hand-placed, ref_tol_deg = {deg:g}':46s} "
                     f"{g_mg(r, rec.raw_g):8.4f} {g_mg(r, other):8.4f}")
    return lines


# --- imu_tk's accelerometer method, for the same-intervals comparison --------------------
IMU_TK_WINDOW = 101  # samples, its staticIntervalsDetector default
IMU_TK_INIT_SAMPLES = 3000  # its n_init_samples: the rest the threshold is scaled from
IMU_TK_INTERVAL_SAMPLES = 100  # its interval_n_samples: minimum length, samples fitted
IMU_TK_TH_MULT = range(2, 11)
IMU_TK_MIN_INTERVALS = 12


def imu_tk_intervals(acc_g: np.ndarray, th_mult: int) -> list[tuple[int, int]]:
    """Runs where the 101-sample variance norm is below ``th_mult`` × the initial rest's;
    ``[start, end)``, kept when at least 100 samples long."""
    h = IMU_TK_WINDOW // 2
    x = acc_g - acc_g[0]
    c1 = np.vstack([np.zeros((1, 3)), np.cumsum(x, 0)])
    c2 = np.vstack([np.zeros((1, 3)), np.cumsum(x * x, 0)])
    i = np.arange(h, len(x) - h)
    m = (c1[i + h + 1] - c1[i - h]) / IMU_TK_WINDOW
    var = ((c2[i + h + 1] - c2[i - h]) - IMU_TK_WINDOW * m * m) / (IMU_TK_WINDOW - 1)
    quiet = np.zeros(len(x), bool)
    quiet[i] = np.linalg.norm(var, axis=1) < th_mult * np.linalg.norm(
        acc_g[: IMU_TK_INIT_SAMPLES + 1].var(axis=0, ddof=1))
    edges = np.flatnonzero(np.diff(np.r_[0, quiet.astype(np.int8), 0]))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)
            if b - a >= IMU_TK_INTERVAL_SAMPLES]


def _imu_tk_residual(p: np.ndarray, y: np.ndarray) -> np.ndarray:
    """|T K (y − b)| − 1 with T K upper triangular (its misYZ, misZY, misZX and scales)."""
    tk = np.array([[p[0], p[1], p[2]], [0.0, p[3], p[4]], [0.0, 0.0, p[5]]])
    return np.linalg.norm((y - p[6:9]) @ tk.T, axis=1) - 1.0


def _imu_tk_fit(y: np.ndarray, p0: np.ndarray | None = None) -> np.ndarray:
    start = np.array([1.0, 0, 0, 1.0, 0, 1.0, 0, 0, 0]) if p0 is None else p0
    return least_squares(_imu_tk_residual, start, args=(y,), method="lm").x


def imu_tk_loo_mg(acc_g: np.ndarray, intervals: list[tuple[int, int]], per_sample: bool
                  ) -> float:
    """Refit without interval i, predict the |g| of interval i's mean; RMS over i, mg."""
    means = np.array([acc_g[a:b].mean(axis=0) for a, b in intervals])
    if per_sample:
        y = np.vstack([acc_g[a:a + IMU_TK_INTERVAL_SAMPLES] for a, _ in intervals])
        owner = np.repeat(np.arange(len(intervals)), IMU_TK_INTERVAL_SAMPLES)
    else:
        y, owner = means, np.arange(len(intervals))
    p_all = _imu_tk_fit(y)
    err = [_imu_tk_residual(_imu_tk_fit(y[owner != k], p_all), means[k:k + 1])[0]
           for k in range(len(intervals))]
    return float(np.sqrt(np.mean(np.square(err))) * 1e3)


def run_same_intervals(name: str, fmt: str, path: Path, options: dict[str, object]
                       ) -> list[str]:
    raw = importers.read_source(fmt, path, **options)
    lines = []
    for th in IMU_TK_TH_MULT:
        iv = imu_tk_intervals(raw.acc_g, th)
        if len(iv) < IMU_TK_MIN_INTERVALS:
            lines.append(f"{name:28s} {th:3d} {len(iv):3d}  fewer than "
                         f"{IMU_TK_MIN_INTERVALS} intervals: imu_tk does not calibrate")
            continue
        rec = importers.intervals_to_recording(raw, iv, path=str(path))
        held = holdout.leave_one_out(rec, fit_campaign(rec))
        ours = _mg(held["loo_rmse_ug"])
        ours_s = f"{ours:8.4f}" if ours is not None else f"{'null':>8s}"
        lines.append(f"{name:28s} {th:3d} {len(iv):3d} {imu_tk_loo_mg(raw.acc_g, iv, True):9.4f} "
                     f"{imu_tk_loo_mg(raw.acc_g, iv, False):9.4f} {ours_s}")
    return lines


def format_same_intervals(lines: list[str]) -> str:
    head = (f"{'dataset':28s} {'th':>3s} {'N':>3s} {'samples':>9s} {'means':>9s} "
            f"{'soakcal':>8s}")
    return "\n".join([head, "-" * len(head), *lines, "",
                      "leave-one-interval-out |g| RMSE, mg, on imu_tk's intervals at th_mult × "
                      "the initial rest; samples / means = imu_tk per sample (its default) / "
                      "on interval means; soakcal = calibrate (sd/√n + model floor)"])


LAYOUTS = (("intervals", []), ("raw", ["--raw"]), ("1-s blocks", ["--block-s", "1"]))


def _soakcal(args: list[str]) -> tuple[int, str, str]:
    import subprocess

    r = subprocess.run([sys.executable, "-m", "service.cli", *args], cwd=ROOT,
                       capture_output=True, text=True, check=False)
    return r.returncode, r.stdout, r.stderr


def run_layouts(name: str, fmt: str, path: Path, options: dict[str, object],
                tmp: Path) -> list[str]:
    """Table rows: calibrate and diagnose on the recording in each layout (``--layouts``)."""
    import json

    extra = [f"--sensor={options['sensor']}"] if "sensor" in options else []
    lines = []
    for layout, flags in LAYOUTS:
        rec = tmp / f"{name.split()[0]}-{layout.split()[0]}.csv"
        status, _, err = _soakcal(["import", "--format", fmt, str(path), "-o", str(rec),
                                   *extra, *flags])
        if status != 0:
            lines.append(f"| {name} | {layout} | import exit {status}: {err.strip()[-120:]} "
                         f"| | |")
            continue
        status, out, err = _soakcal(["calibrate", str(rec), "-o", str(tmp / "m.json"),
                                     "--json"])
        if status == 0:
            doc = json.loads(out)
            loo = doc.get("loo_rmse_ug")
            spare = (doc.get("dof") or {}).get("spare")
            cal = (f"exit 0: {doc.get('mode')}, {doc.get('orientations')} orientations, "
                   f"{doc.get('rows')} rows, spare {spare}, LOO "
                   f"{'null' if loo is None else f'{loo / 1e3:.3f} mg'}")
        else:
            cal = f"exit {status}: {err.strip().split(': ', 2)[-1][:150]}"
        status, out, err = _soakcal(["diagnose", str(rec), "--json"])
        if status == 0:
            doc = json.loads(out)
            base = doc.get("baseline") or {}
            rmse = base.get("rmse_ug")
            diag = (f"{doc.get('verdict')}"
                    + (f", rmse {rmse / 1e3:.3f} mg" if rmse is not None else "")
                    + (f", {', '.join(f['effect'] for f in doc.get('findings', []))}"
                       if doc.get("findings") else ""))
        else:
            diag = f"exit {status}"
        lines.append(f"| {name} | {layout} | {cal} | {diag} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", type=Path, default=Path(os.environ.get(
        "SOAKCAL_REALDATA", Path(__file__).resolve().parents[1] / "tests/data/realdata")))
    ap.add_argument("--peers-only", action="store_true",
                    help="only imu_tk's method and soakcal's fit on the same intervals")
    ap.add_argument("--layouts", action="store_true",
                    help="calibrate and diagnose each recording as intervals, raw samples "
                         "and 1-s blocks")
    args = ap.parse_args(argv)
    if not args.realdata.is_dir():
        print(f"no real data at {args.realdata}", file=sys.stderr)
        return 2
    if args.layouts:
        import tempfile

        print("| recording | layout | calibrate | diagnose |\n|---|---|---|---|")
        with tempfile.TemporaryDirectory() as tmp:
            for name, fmt, rel, options in DATASETS:
                if (args.realdata / rel).exists() and "annotated" not in name:
                    print("\n".join(run_layouts(name, fmt, args.realdata / rel, options,
                                                Path(tmp))), flush=True)
        return 0
    rows: list[Row] = []
    defaults: list[DefaultsRow] = []
    ferraris: list[str] = []
    same: list[str] = []
    for name, fmt, rel, options in DATASETS:
        path = args.realdata / rel
        if not path.exists():
            print(f"skip {name}: {path} missing", file=sys.stderr)
            continue
        if fmt != "ferraris":
            same += run_same_intervals(name, fmt, path, options)
        if args.peers_only:
            continue
        rows += run_dataset(name, fmt, path, options)
        if fmt == "ferraris":
            ferraris += run_ferraris(path)
        else:
            defaults.append(run_defaults(name, fmt, path, options))
    print("== imu_tk's method and soakcal's fit on the same intervals, mg of |g| ==")
    print(format_same_intervals(same))
    if args.peers_only:
        return 0
    print("\n== soakcal defaults (import + calibrate, no flags) vs peer tools, mg of |g| ==")
    print(format_defaults(defaults))
    print("\n== hand-placed Ferraris positions: |g| RMSE, mg ==")
    print("\n".join(ferraris))
    print("\n== weights, format-default detector: equal, sd/√n alone, sd/√n + floor ==")
    print(format_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
