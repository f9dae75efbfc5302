"""One-orientation warm-ups: PX4's and ArduPilot's thermal calibration beside soakcal's.

Usage::

    .venv/bin/python -m benchmarks.bench_warmup_peers [--out DIR] [--realdata DIR]
        [--log FILE ... [--log-format ulog|dataflash|csv] [--import-args "..."]] [--no-twin]

Each log is a board at rest at one orientation while its temperature changes: raw
samples (t, acceleration in g, the sensor's temperature reading). Its 10-s blocks
are alternately *fit* (even) and *held out* (odd). Each method fits on the fit blocks'
samples only and compensates every sample; the figure per axis is the RMS, over the
held-out blocks' 5-s means, of the compensated mean minus the mean of the compensated
fit-block samples (the gravity projection of one orientation is an unknown constant,
so only the change with temperature counts). In mg.

Methods:

* ``none``: no compensation (the constant only).
* ``px4``: the method of PX4's ``Tools/process_sensor_caldata.py``, re-implemented here
  from its public source (:func:`px4_script_fit`): per axis a 31-sample median filter,
  the reading less its median, averaged in 2000 equal temperature bins
  (``resampleWithDeltaX``), and ``numpy.polyfit`` of order 3 against (T − TREF), TREF the
  middle of the temperature span; the offset is subtracted with T clamped to the fit
  span (``calc_thermal_offsets_3D``).
* ``ardupilot``: ArduPilot's ``tempcal_IMU.py`` as shipped in the
  ``ardupilot-methodic-configurator`` package (used when it is installed: its
  ``IMUData`` 2-s moving-average filter and its order-3 fit vs T − 35 °C); otherwise
  the same steps re-implemented (the table says which). Offset applied with T clamped
  to the fit span, as the firmware does.
* ``soakcal``: the fit blocks as 1-s mean rows (``soakcal import --block-s 1``'s
  layout: mean, sd, n, mean ``sensor_c``), ``soakcal calibrate``, then ``soakcal
  compensate`` of every 1-s row of the log, its temperature clamped to the fit rows'
  span (as the firmwares clamp); a refusal (exit 2) is reported as such. A model with a
  rate term k·dT/dt has the clamp on its polynomial only: its rate term is compensated
  from the unclamped temperatures (a clamped column reads dT/dt = 0 beyond the span).
* ``--fixed-degrees``: also each fixed degree 0 … 3 fitted the way soakcal fits a
  warm-up (least squares on the fit blocks' 1-s rows, each at its own mean temperature;
  every sample compensated at its 1-s row's temperature, clamped to the fit rows'
  span): what each degree would score, beside the one soakcal's held-out error chose.
* ``--whole``: soakcal also as a user runs it on a raw log, every sample a row in the
  layout ``soakcal import`` writes (``t_s, sensor_c, ax, ay, az, n``), read by
  ``calibrate`` and ``compensate`` through their own capture reader (5-s capture means):
  (a) held out: ``calibrate`` on the fit blocks' samples, ``compensate`` of every sample
  (``--extrapolate``, no clamp: the user's command), scored as above; (b) the whole log:
  ``calibrate`` and ``compensate`` on every sample, scored in-sample as the RMS of all
  full 5-s means about their mean (beside the same figure uncompensated). A refusal
  (exit 2) is reported with its line.
* ``--export``: also the file ``soakcal export --format px4`` writes from soakcal's model,
  applied as PX4 applies it (``calc_thermal_offsets_3D``: the offset at each sample's own
  reading clamped to TMIN/TMAX): ``export`` as written (a model with a rate term: the
  term's mean at each reading folded into the polynomial, ``firmware_polynomial.rate_fold_record``)
  and ``export drop`` (the model's ``rate_fold`` record removed: the static polynomial,
  the rate term dropped, as the export wrote before the fold). ArduPilot's file is the same
  polynomial less a constant, so its held-out figure is the same.
* ``--as-flown``: also each firmware's file as the firmware applies it in flight
  (:mod:`calibration.firmware_flight`, read from their source): PX4 evaluates its offset
  at the reading of a 1-s poll and publishes it only when the reading moved by more than
  1 °C since the last publication; ArduPilot's InvenSense backends hand ``correct_accel``
  the reading through a 2-pole 1-Hz low-pass. The peers' own files (PX4's script's
  through the gate, ArduPilot's tempcal through the filter) and, with ``--export``,
  soakcal's exported file through each, with soakcal's over the same firmware's peer.
* ``floor``: the noise floor of a held-out 5-s mean: the RMS difference of the two
  5-s means inside each held-out block, divided by √2 (white noise; slow drift cancels).

Logs: the twin (``simulators``: an ADXL355-class sensor drawn at random, z up, the die
warming from 25 °C toward 45 °C with a 10-min time constant, then after 24 min cooling
toward 30 °C; 40 min at 50 Hz) as is, with a
temperature-rate sensitivity, with the temperature channel lagging the die by 60 s,
and both; plus the BMI270 real logs (``bmi270-ganesh``: one orientation per file); plus
any ``--log FILE``: read by ``soakcal import --format ulog|dataflash|csv`` (every sample a
row, the import's own conversions and checks) and compared the same way. A log whose
import is refused or keeps no measured temperature (a simulator's 0.00 °C) is listed as
not compared, with the import's reason.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration.discrepancy.effects.temperature_rate import rate_offset_g
from calibration.recording import read_recording
from calibration.thermal_plant import lag_series
from simulators.truth import SensorTruth

BLOCK_S = 10.0
MEAN_S = 5.0
ROW_S = 1.0
REPO = Path(__file__).resolve().parents[1]
# soakcal of this tree (``python -m`` from the repository root), not whichever install the
# interpreter's console script points at.
SOAKCAL = [sys.executable, "-m", "service.cli"]
LOG_SUFFIX_FORMAT = {".ulg": "ulog", ".bin": "dataflash"}


@dataclass
class WarmupLog:
    name: str
    t_s: np.ndarray  # (N,)
    acc_g: np.ndarray  # (N,3)
    temp_c: np.ndarray  # (N,) the temperature channel the methods see


# --- logs --------------------------------------------------------------------------

def xyz_mg(v: object, digits: int = 4, missing: str = "—") -> str:
    """Three figures x / y / z (mg) as the tables print them; ``missing`` for None."""
    if v is None:
        return missing
    return " / ".join(f"{x:.{digits}f}" for x in v)  # type: ignore[attr-defined]

def twin_log(name: str, *, rate_ug_per_c_per_min: float = 0.0, channel_lag_s: float = 0.0,
             seed: int = 7, minutes: float = 40.0, rate_hz: float = 50.0,
             tau_s: float = 600.0, noise_seed: int | None = None,
             noiseless: bool = False) -> WarmupLog:
    """The twin's sensor at rest (z up): its die warms from 25 °C toward 45 °C (τ
    ``tau_s``, 10 min) for the first 60 % of the log, then cools toward 30 °C (a heater
    switched off).

    Warming and cooling both: in a monotonic warm-up a rate effect or a lagging channel
    is itself a function of the temperature and any polynomial in T absorbs it.
    ``noise_seed`` (default ``seed``): the noise's seed; the sensor is drawn from ``seed``,
    so another noise seed (and ``tau_s``) is the same sensor's other warm-up.
    ``noiseless``: the acceleration without its noise (the log's truth)."""
    rng = np.random.default_rng(seed if noise_seed is None else noise_seed)
    truth = SensorTruth.adxl355_typical(seed=seed, odr_hz=rate_hz)
    n = int(minutes * 60 * rate_hz)
    t = np.arange(n) / rate_hz
    t_off = 0.6 * t[-1]
    hot = 25.0 + 20.0 * (1.0 - np.exp(-t / tau_s))
    at_off = 25.0 + 20.0 * (1.0 - np.exp(-t_off / tau_s))
    die = np.where(t <= t_off, hot, 30.0 + (at_off - 30.0) * np.exp(-(t - t_off) / tau_s))
    ref = np.tile([0.0, 0.0, 1.0], (n, 1))
    acc = truth.ideal_raw_g(ref, die)
    if rate_ug_per_c_per_min:
        k = np.array([1.0, -0.6, 0.8]) * rate_ug_per_c_per_min * 1e-6 * 60.0  # per °C/s
        acc = acc + rate_offset_g(np.gradient(die, t), k)
    if not noiseless:
        acc = acc + rng.normal(0.0, truth.sample_sd_g(), acc.shape)
    channel = lag_series(die, 1.0 / rate_hz, channel_lag_s) if channel_lag_s else die
    temp = channel + truth.temp_offset_c + rng.normal(0.0, truth.temp_noise_c, n)
    return WarmupLog(name, t, acc, temp)


def bmi270_logs(folder: Path) -> list[WarmupLog]:
    """The BMI270 files: ``temp_C, ax, ay, az, gx, gy, gz``, accel printed as g/4, ~50 Hz
    with no time column (the firmware's 20 ms loop); lines that do not parse are skipped."""
    out = []
    for path in sorted(folder.glob("BMI_270_*.csv")):
        rows = []
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            cells = line.split(",")
            if len(cells) != 7:
                continue
            try:
                vals = [float(c) for c in cells[:4]]
            except ValueError:
                continue
            if vals[0] <= 0.0:  # the hot log's truncated first line reads 0 °C
                continue
            rows.append(vals)
        data = np.asarray(rows)
        t = np.arange(data.shape[0]) / 50.0
        out.append(WarmupLog(f"bmi270 {path.stem}", t, data[:, 1:4] * 4.0, data[:, 0]))
    return out


def imported_log(path: Path, fmt: str, import_args: list[str],
                 workdir: Path) -> tuple[WarmupLog | None, str]:
    """Any log through ``soakcal import --format FMT`` (every sample a row), read back.

    Returns the log, or None and why it cannot be compared: the import's refusal, or a
    recording without a measured temperature (the import's note says which).
    """
    rec_path = workdir / f"{path.stem}.import.csv"
    run = subprocess.run([*SOAKCAL, "import", "--format", fmt, str(path), "-o", str(rec_path),
                          *import_args], capture_output=True, text=True, cwd=REPO)
    if run.returncode != 0:
        return None, f"import exit {run.returncode}: {_last_line(run.stderr)}"
    rec = read_recording(rec_path)
    notes = [ln.strip()[6:] for ln in run.stdout.splitlines() if ln.strip().startswith("note:")]
    if not rec.has("sensor_c"):
        said = [n for n in notes if "temperature" in n]
        return None, "no measured temperature: " + (said[-1] if said else "none in the log")
    log = WarmupLog(f"{path.name} ({fmt})", np.asarray(rec.t_s, float),
                    np.asarray(rec.raw_g, float), np.asarray(rec.columns["sensor_c"], float))
    short = too_few_means(log)
    return (None, short) if short else (log, "; ".join(notes))


def too_few_means(log: WarmupLog, minimum: int = 4) -> str | None:
    """Why the split cannot score this log (fewer than ``minimum`` full held-out 5-s
    means, or no fit block), else None."""
    if log.t_s.size < 2 or log.t_s[-1] <= log.t_s[0]:
        return f"{log.t_s.size} sample(s): no time series"
    k, fit = blocks(log.t_s)
    half = np.floor((log.t_s - log.t_s[0]) / MEAN_S).astype(int)
    full = [h for h in np.unique(half[~fit]) if np.sum(half == h) > 0.8 * MEAN_S * _rate(log)]
    if len(full) >= minimum and fit.any():
        return None
    return (f"{log.t_s.size} samples over {log.t_s[-1] - log.t_s[0]:.0f} s "
            f"({_rate(log):.3g} Hz): {len(full)} full held-out 5-s means, "
            f"{minimum} needed")


# --- split and metric -----------------------------------------------------------------
def blocks(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(block index of each sample, True where the sample is in a fit block)."""
    k = np.floor((t_s - t_s[0]) / BLOCK_S).astype(int)
    return k, k % 2 == 0


def heldout_rms_mg(log: WarmupLog, compensated_g: np.ndarray) -> np.ndarray:
    """Per axis: RMS of held-out 5-s means minus the mean over the fit samples (mg)."""
    k, fit = blocks(log.t_s)
    ref = compensated_g[fit].mean(axis=0)
    half = np.floor((log.t_s - log.t_s[0]) / MEAN_S).astype(int)
    means = [compensated_g[half == h].mean(axis=0) for h in np.unique(half[~fit])
             if np.sum(half == h) > 0.8 * MEAN_S * _rate(log)]
    return np.sqrt(np.mean((np.asarray(means) - ref) ** 2, axis=0)) * 1e3


def noise_floor_mg(log: WarmupLog) -> np.ndarray:
    k, fit = blocks(log.t_s)
    half = np.floor((log.t_s - log.t_s[0]) / MEAN_S).astype(int)
    diffs = []
    for b in np.unique(k[~fit]):
        hs = np.unique(half[k == b])
        if hs.size == 2 and all(np.sum(half == h) > 0.8 * MEAN_S * _rate(log) for h in hs):
            diffs.append(log.acc_g[half == hs[0]].mean(axis=0)
                         - log.acc_g[half == hs[1]].mean(axis=0))
    return np.sqrt(np.mean(np.asarray(diffs) ** 2, axis=0) / 2.0) * 1e3


def _rate(log: WarmupLog) -> float:
    return (log.t_s.size - 1) / (log.t_s[-1] - log.t_s[0])


# --- methods ---------------------------------------------------------------------------
def method_none(log: WarmupLog) -> np.ndarray:
    return log.acc_g


PX4_MEDIAN_KERNEL = 31  # process_sensor_caldata.py: median_filter = medfilt(data, 31)
PX4_RESAMPLE_BINS = 2000  # resampleWithDeltaX: nbInterval


def px4_script_fit(log: WarmupLog, fit: np.ndarray, *, resample: bool = True
                   ) -> tuple[np.ndarray, float, float, float]:
    """PX4's ``Tools/process_sensor_caldata.py`` accelerometer fit (its accel 0–2 branch),
    written from its public source: each axis through a 31-sample median filter
    (``scipy.signal.medfilt``: zero-padded ends; here each contiguous run of ``fit``
    samples separately, as a log with the held-out blocks cut out), less its median; then,
    by default, ``resampleWithDeltaX``: 2000 equal bins over the temperature span, each
    non-empty bin's mean temperature and mean correction; a cubic ``polyfit`` against
    T − TREF, TREF the middle of TMIN..TMAX (the raw temperature's extremes). Without
    ``resample`` (the script's ``--no_resample``) the cubic is fitted to every sample.

    Returns ((3, 4) highest power first, as ``np.polyfit``; TMIN, TMAX, TREF)."""
    from scipy.signal import medfilt

    T = log.temp_c[fit]
    t_min, t_max = float(T.min()), float(T.max())
    t_ref = 0.5 * (t_min + t_max)
    rel = T - t_ref
    filtered = np.vstack([np.column_stack([medfilt(log.acc_g[m, i], PX4_MEDIAN_KERNEL)
                                           for i in range(3)])
                          for m in fit_runs(fit, log.t_s)])
    # fit_runs keeps file order, so the runs' rows line up with log.temp_c[fit]
    coef = np.empty((3, 4))
    for i in range(3):
        corr = filtered[:, i] - np.median(filtered[:, i])
        x, y = _resample_with_delta_x(rel, corr) if resample else (rel, corr)
        coef[i] = np.polyfit(x, y, 3)
    return coef, t_min, t_max, t_ref


def _resample_with_delta_x(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``resampleWithDeltaX``: the mean x and y of each non-empty one of 2000 equal bins
    over x's span (a value at the top in the last bin), in bin order."""
    lo, hi = float(np.min(x)), float(np.max(x))
    width = (hi - lo) / PX4_RESAMPLE_BINS
    idx = np.where(x < hi, ((x - lo) / width if width > 0 else 0 * x), PX4_RESAMPLE_BINS - 1)
    idx = np.minimum(idx.astype(int), PX4_RESAMPLE_BINS - 1)
    count = np.bincount(idx, minlength=PX4_RESAMPLE_BINS)
    keep = count > 0
    return ((np.bincount(idx, x, PX4_RESAMPLE_BINS) / np.maximum(count, 1))[keep],
            (np.bincount(idx, y, PX4_RESAMPLE_BINS) / np.maximum(count, 1))[keep])


def method_px4(log: WarmupLog, fit: np.ndarray | None = None,
               applied_at_c: np.ndarray | None = None) -> np.ndarray:
    """process_sensor_caldata.py's accel fit (:func:`px4_script_fit`), applied as
    calc_thermal_offsets_3D does (fitted to the ``fit`` samples: default the fit blocks),
    at each sample's reading or at ``applied_at_c`` (``--as-flown``: :func:`flown_readings`)."""
    if fit is None:
        _, fit = blocks(log.t_s)
    coef, t_min, t_max, t_ref = px4_script_fit(log, fit)
    out = np.empty_like(log.acc_g)
    d = np.clip(log.temp_c if applied_at_c is None else applied_at_c, t_min, t_max) - t_ref
    for i in range(3):
        out[:, i] = log.acc_g[:, i] - np.polyval(coef[i], d)
    return out


def method_ardupilot(log: WarmupLog, fit: np.ndarray | None = None,
                     applied_at_c: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """tempcal_IMU.py: 2-s moving average of X, Y, Z, T and time, order-3 fit vs T − 35
    (fitted to the ``fit`` samples: default the fit blocks), applied at each sample's
    reading or at ``applied_at_c`` (``--as-flown``: :func:`flown_readings`)."""
    if fit is None:
        _, fit = blocks(log.t_s)
    try:
        from ardupilot_methodic_configurator import tempcal_imu as tc
        source = "ardupilot-methodic-configurator tempcal_imu"
    except ImportError:
        tc, source = None, "re-implemented (package not installed)"
    # each contiguous run of fit samples separately (the split's fit blocks): the moving
    # average must not run across held-out gaps
    xs, ts = [], []
    for m in fit_runs(fit, log.t_s):
        cols = {"X": log.acc_g[m, 0], "Y": log.acc_g[m, 1], "Z": log.acc_g[m, 2],
                "T": log.temp_c[m], "time": log.t_s[m]}
        if tc is not None:
            cols = tc.IMUData().filter_array(dict(cols), 2)
        else:
            cols = _moving_average_2s(cols)
        xs.append(np.column_stack([cols["X"], cols["Y"], cols["Z"]]))
        ts.append(cols["T"])
    X, T = np.vstack(xs), np.concatenate(ts)
    temp_ref = tc.TEMP_REF if tc is not None else 35.0
    order = tc.POLY_ORDER if tc is not None else 3
    t_min, t_max = float(T.min()), float(T.max())
    out = np.empty_like(log.acc_g)
    at = log.temp_c if applied_at_c is None else applied_at_c
    for i in range(3):
        coef = np.polyfit(T - temp_ref, X[:, i] - X[:, i].mean(), order)
        out[:, i] = log.acc_g[:, i] - np.polyval(coef, np.clip(at, t_min, t_max) - temp_ref)
    return out, source


def fit_runs(fit: np.ndarray, t_s: np.ndarray | None = None) -> list[np.ndarray]:
    """Boolean masks of the contiguous runs of True in ``fit`` (the split's fit blocks;
    one run for a whole log), a run also broken where ``t_s`` skips more than a block
    (a dropout)."""
    idx = np.flatnonzero(fit)
    cut = np.diff(idx) > 1
    if t_s is not None:
        cut |= np.diff(t_s[idx]) > BLOCK_S
    runs = np.split(idx, np.flatnonzero(cut) + 1) if idx.size else []
    out = []
    for r in runs:
        m = np.zeros(fit.size, bool)
        m[r] = True
        out.append(m)
    return out


def _moving_average_2s(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    n = cols["time"].size
    w = int(n / (cols["time"][-1] - cols["time"][0])) * 2
    if w <= 1:
        return cols
    out = {}
    for key, v in cols.items():
        c = np.cumsum(v)
        c[w:] = c[w:] - c[:-w]
        out[key] = c[w - 1:] / w
    return out


def method_fixed_degree(log: WarmupLog, degree: int) -> np.ndarray:
    """A polynomial of ``degree`` in T fitted as soakcal fits a warm-up (the fit blocks'
    1-s rows at their own mean temperatures; x = (T − mid) / max(half span, 1 °C)) and
    applied at each sample's 1-s row temperature clamped to the fit rows' span."""
    _, fit = blocks(log.t_s)
    rows = np.asarray(rows_1s(log, fit))
    T, acc = rows[:, 1], rows[:, 2:5]
    lo, hi = float(T.min()), float(T.max())
    centre, scale = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1.0)
    beta, *_ = np.linalg.lstsq(np.vander((T - centre) / scale, degree + 1, increasing=True),
                               acc, rcond=None)
    sec = np.floor((log.t_s - log.t_s[0]) / ROW_S).astype(int)
    row_c = np.bincount(sec, weights=log.temp_c) / np.maximum(np.bincount(sec), 1)
    x = (np.clip(row_c[sec], lo, hi) - centre) / scale
    return log.acc_g - np.vander(x, degree + 1, increasing=True)[:, 1:] @ beta[1:]


def rows_1s(log: WarmupLog, mask: np.ndarray) -> list[list[float]]:
    """1-s mean rows (t_s, sensor_c, ax, ay, az, n, sd_x, sd_y, sd_z) of the masked samples."""
    sec = np.floor((log.t_s - log.t_s[0]) / ROW_S).astype(int)
    rows = []
    for s in np.unique(sec[mask]):
        m = (sec == s) & mask
        if m.sum() < 2:
            continue
        a = log.acc_g[m]
        rows.append([float(log.t_s[m].mean()), float(log.temp_c[m].mean()), *a.mean(axis=0),
                     float(m.sum()), *a.std(axis=0, ddof=1)])
    return rows


def _write_rows(path: Path, rows: list[list[float]]) -> None:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "sensor_c", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z"])
        w.writerows([[repr(float(v)) for v in r] for r in rows])


def method_soakcal(log: WarmupLog, workdir: Path, fit: np.ndarray | None = None,
                   apply_to: WarmupLog | None = None) -> tuple[np.ndarray | None, str]:
    """``soakcal calibrate`` on the ``fit`` samples' 1-s rows (default the fit blocks),
    ``compensate`` on all 1-s rows of ``apply_to`` (default ``log``: another log of the
    same sensor is compensated by the model of this one).

    Returns the compensated value of every sample (its 1-s row's output minus that row's
    raw mean, added to the sample: the model is smooth over 1 s) or None and the reason.
    """
    if fit is None:
        _, fit = blocks(log.t_s)
    fit_csv, all_csv = workdir / "fit.csv", workdir / "all.csv"
    model, comp = workdir / "model.json", workdir / "comp.csv"
    fit_rows = rows_1s(log, fit)
    _write_rows(fit_csv, fit_rows)
    log = apply_to or log
    all_rows = rows_1s(log, np.ones(log.t_s.size, bool))
    # Temperatures clamped to the fit rows' span, as both firmwares clamp to TMIN/TMAX:
    # a held-out row a little beyond the fitted span is compensated at its edge.
    t_lo, t_hi = min(r[1] for r in fit_rows), max(r[1] for r in fit_rows)
    _write_rows(all_csv, [[r[0], min(max(r[1], t_lo), t_hi), *r[2:]] for r in all_rows])
    t0 = time.perf_counter()
    cal = subprocess.run([*SOAKCAL, "calibrate", str(fit_csv), "-o", str(model), "--json"],
                         capture_output=True, text=True, cwd=REPO)
    fit_s = time.perf_counter() - t0
    if cal.returncode != 0:
        return None, f"calibrate exit {cal.returncode}: {_last_line(cal.stderr)}"
    delta, why = _compensate_delta(model, all_csv, comp)
    if delta is None:
        return None, why
    rate = json.loads(model.read_text()).get("temperature", {}).get("rate")
    if rate:
        # The clamp is the polynomial's (the firmwares clamp T to TMIN/TMAX); dT/dt is
        # the channel's own and is not clamped (a clamped column reads dT/dt = 0 beyond
        # the fit span). Rate term = the model on the unclamped rows less the model
        # without it on them; polynomial = the model without it on the clamped rows.
        raw_csv = workdir / "all_unclamped.csv"
        _write_rows(raw_csv, all_rows)
        no_rate = workdir / "model_no_rate.json"
        doc = json.loads(model.read_text())
        doc["temperature"]["rate"] = None
        no_rate.write_text(json.dumps(doc))
        parts = [_compensate_delta(m, f, comp)[0]
                 for m, f in ((no_rate, all_csv), (model, raw_csv), (no_rate, raw_csv))]
        if any(p is None for p in parts):
            return None, "compensate of the rate term's parts failed"
        delta = parts[0] + (parts[1] - parts[2])  # type: ignore[operator]
    sec = np.floor((log.t_s - log.t_s[0]) / ROW_S).astype(int)
    row_of_sec = {int(np.floor(r[0] - log.t_s[0])): i for i, r in enumerate(all_rows)}
    idx = np.array([row_of_sec.get(int(s), -1) for s in sec])
    keep = idx >= 0
    out = np.full_like(log.acc_g, np.nan)
    out[keep] = log.acc_g[keep] + delta[idx[keep]]
    try:
        info = json.loads(cal.stdout)
        note = f"calibrate {fit_s:.1f} s; " + ", ".join(
            f"{k}={info[k]}" for k in ("mode", "dof") if k in info)
    except ValueError:
        note = f"calibrate {fit_s:.1f} s"
    return out, note


def method_export(log: WarmupLog, model_path: Path, fold: bool = True,
                  applied_at_c: np.ndarray | None = None,
                  firmware: str = "px4") -> np.ndarray:
    """(N,3) compensated by the PX4 file soakcal exports from ``model_path`` (``firmware``
    "ardupilot": the ArduPilot file, its constant left to INS_ACCOFFS), applied at each
    sample's own reading (``--export``) or at ``applied_at_c`` (``--as-flown``); ``fold``
    False: the model's ``rate_fold`` record removed first (the static polynomial)."""
    from benchmarks.bench_export_quantised import ardupilot_offset_g, px4_offset_g
    from calibration.export_firmware import export_ardupilot, export_px4
    from calibration.model_file import load_model

    model = load_model(model_path)
    if not fold:
        model.provenance.pop("rate_fold", None)
    at = log.temp_c if applied_at_c is None else applied_at_c
    if firmware == "ardupilot":
        return log.acc_g - ardupilot_offset_g(export_ardupilot(model).text, at)
    return log.acc_g - px4_offset_g(export_px4(model).text, at)


def fit_blocks_rms_mg(log: WarmupLog, compensated_g: np.ndarray) -> np.ndarray:
    """Per axis: RMS of the fit blocks' 5-s means minus the mean over the fit samples (mg):
    :func:`heldout_rms_mg` on the blocks the model was fitted on (in-sample)."""
    _, fit = blocks(log.t_s)
    ref = compensated_g[fit].mean(axis=0)
    half = np.floor((log.t_s - log.t_s[0]) / MEAN_S).astype(int)
    means = [compensated_g[half == h].mean(axis=0) for h in np.unique(half[fit])
             if np.sum(half == h) > 0.8 * MEAN_S * _rate(log)]
    return np.sqrt(np.mean((np.asarray(means) - ref) ** 2, axis=0)) * 1e3


def stated_vs_measured(log: WarmupLog, model_path: Path, soakcal_g: np.ndarray
                       ) -> dict[str, object]:
    """The RMS (file − model) the PX4 header states for its file, and what it measures:
    the file applied at each sample's reading less ``soakcal compensate``'s offset, over
    the fit blocks' 5-s means (in-sample, as stated) and the held-out ones. The stated
    figure is the reading record's (a rebuilt coarse channel) or the FOLDED line's (a
    fine channel with a rate term); a fine channel without one writes the model's b(T)
    and states none. With the fit's own held-out RMS, which the header states beside it."""
    from calibration.export_firmware import firmware_reading_record
    from calibration.model_file import load_model

    model = load_model(model_path)
    record = firmware_reading_record(model) or {}
    fold = model.provenance.get("rate_fold") or {}
    if record:
        what, stated, fit = "reading", record.get("rms_mg"), record.get("fit_heldout_mg")
    elif fold.get("folded_rate_x_g") is not None:
        what, stated, fit = "folded", fold.get("rms_mg"), fold.get("fit_heldout_mg")
    else:
        what, stated, fit = "b(T)", None, None
    ok = np.all(np.isfinite(soakcal_g), axis=1)
    sub = WarmupLog(log.name, log.t_s[ok], log.acc_g[ok], log.temp_c[ok])
    diff = method_export(log, model_path)[ok] - soakcal_g[ok]
    return {"stated_what": what, "stated_rms_mg": stated, "stated_fit_heldout_mg": fit,
            "file_vs_model_fit_mg": fit_blocks_rms_mg(sub, diff).tolist(),
            "file_vs_model_heldout_mg": heldout_rms_mg(sub, diff).tolist()}


def stated_table(results: list[dict[str, object]]) -> str:
    """The header's stated RMS (file − model) against the measured, in-sample and held
    out, and the file's and the fit's own held-out error, mg x / y / z."""
    lines = ["| log | stated of | stated RMS (file − model) | fit blocks file − model | "
             "held-out file − model | file held out | fit's own held-out (stated) |",
             "|---|---|---|---|---|---|---|"]

    fmt = xyz_mg

    for r in results:
        if "stated_what" in r:
            lines.append(f"| {r['log']} | {r['stated_what']} | {fmt(r['stated_rms_mg'])} | "
                         f"{fmt(r['file_vs_model_fit_mg'])} | "
                         f"{fmt(r['file_vs_model_heldout_mg'])} | "
                         f"{fmt(r.get('export', r.get('export_at_raw')))} | "
                         f"{fmt(r['stated_fit_heldout_mg'])} |")
    return "\n".join(lines)


def flown_readings(log: WarmupLog) -> dict[str, np.ndarray]:
    """(``--as-flown``) the temperature each firmware evaluates its offset at, per sample:
    PX4's 1-s poll and 1 °C publication gate, ArduPilot's InvenSense 1-Hz low-pass
    (:mod:`calibration.firmware_flight`, read from their source)."""
    from calibration.firmware_flight import ardupilot_reading_in_use, px4_reading_in_use

    return {"px4": px4_reading_in_use(log.t_s, log.temp_c),
            "ardupilot": ardupilot_reading_in_use(log.t_s, log.temp_c)}


def evaluate_flown(log: WarmupLog, model_path: Path | None,
                   window_s: float = 2 * BLOCK_S) -> dict[str, object]:
    """(``--as-flown``) the held-out error of each firmware's file as the firmware applies
    it (:func:`flown_readings`): the peers' own files (PX4's script's through PX4's gate,
    ArduPilot's tempcal through ArduPilot's filter) and, with a model, soakcal's exported
    file through each (its ``--format px4`` and ``--format ardupilot`` files); soakcal's
    over the same firmware's peer with a 95 % paired bootstrap over ``window_s`` windows."""
    from benchmarks.bench_export_quantised import ratio_interval

    at = flown_readings(log)
    px4 = method_px4(log, applied_at_c=at["px4"])
    ardupilot = method_ardupilot(log, applied_at_c=at["ardupilot"])[0]
    res: dict[str, object] = {"px4_flown": heldout_rms_mg(log, px4).tolist(),
                              "ardupilot_flown": heldout_rms_mg(log, ardupilot).tolist(),
                              "px4_publications": int(np.unique(at["px4"]).size)}
    if model_path is not None:
        res |= gate_departure(log, model_path, at["px4"])
        for fw, peer in (("px4", px4), ("ardupilot", ardupilot)):
            ours = method_export(log, model_path, applied_at_c=at[fw], firmware=fw)
            res[f"export_flown_{fw}"] = heldout_rms_mg(log, ours).tolist()
            res[f"export_flown_{fw}_over_peer_95"] = ratio_interval(log.t_s, ours, (peer,),
                                                                    window_s)
    return res


def gate_departure(log: WarmupLog, model_path: Path, in_use_c: np.ndarray
                   ) -> dict[str, object]:
    """The PX4 header's stated figure for its gate (``export_firmware.px4_update_gate``, per
    axis mg) beside the largest departure, on this log, of the offset in use (the file at
    ``in_use_c``) from the file's offset at each sample's reading."""
    import re

    from benchmarks.bench_export_quantised import px4_offset_g
    from calibration.export_firmware import export_px4
    from calibration.model_file import load_model

    text = export_px4(load_model(model_path)).text
    (line,) = [x for x in text.splitlines() if "update_offsets_accel" in x]
    m = re.search(r"up to ([-0-9.]+) / ([-0-9.]+) / ([-0-9.]+) mg \(x / y / z\)", line)
    departure = np.abs(px4_offset_g(text, in_use_c) - px4_offset_g(text, log.temp_c))
    moved = np.abs(in_use_c - log.temp_c)
    return {"gate_stated_mg": None if m is None else [float(v) for v in m.groups()],
            "gate_departure_max_mg": (departure.max(axis=0) * 1e3).tolist(),
            "gate_reading_max_c": float(moved.max())}


def flown_table(results: list[dict[str, object]]) -> str:
    """(``--as-flown``) mg x / y / z: each file per sample and as its firmware flies it."""
    lines = ["| log | PX4 script per sample | PX4 script flown | export per sample | export "
             "flown PX4 | ÷ PX4 script flown (95 %) | ArduPilot tempcal per sample | "
             "ArduPilot flown | export flown ArduPilot | ÷ ArduPilot flown (95 %) |",
             "|---|---|---|---|---|---|---|---|---|---|"]

    fmt = xyz_mg

    def ci(r: dict[str, object], fw: str) -> str:
        ours = r.get(f"export_flown_{fw}")
        if ours is None:
            return "—"
        ratio = np.asarray(ours) / np.asarray(r[f"{fw}_flown"])
        return " / ".join(f"{x:.3f} ({a:.2f}–{b:.2f})" for x, (a, b) in zip(
            ratio, r[f"export_flown_{fw}_over_peer_95"], strict=True))  # type: ignore[call-overload]

    for r in results:
        if "px4_flown" in r:
            lines.append(
                f"| {r['log']} | {fmt(r['px4'])} | {fmt(r['px4_flown'])} | "
                f"{fmt(r.get('export'))} | {fmt(r.get('export_flown_px4'))} | {ci(r, 'px4')} | "
                f"{fmt(r['ardupilot'])} | {fmt(r['ardupilot_flown'])} | "
                f"{fmt(r.get('export_flown_ardupilot'))} | {ci(r, 'ardupilot')} |")
    gated = [r for r in results if "gate_departure_max_mg" in r]
    if gated:
        lines += ["", "| log | PX4 header: gate figure | largest departure on the log | "
                  "largest distance of the reading in use (°C) |", "|---|---|---|---|"]
        lines += [f"| {r['log']} | {fmt(r['gate_stated_mg'])} | "
                  f"{fmt(r['gate_departure_max_mg'])} | {r['gate_reading_max_c']:.3f} |"
                  for r in gated]
    return "\n".join(lines)


def _write_raw(path: Path, log: WarmupLog, mask: np.ndarray) -> None:
    """The masked samples as ``soakcal import`` writes a raw log: one row per sample."""
    cols = np.column_stack([log.t_s[mask], log.temp_c[mask], log.acc_g[mask],
                            np.ones(int(mask.sum()))])
    np.savetxt(path, cols, delimiter=",", fmt=["%.6f", "%.6g", "%.9g", "%.9g", "%.9g", "%d"],
               header="t_s,sensor_c,ax,ay,az,n", comments="")


def method_soakcal_raw(log: WarmupLog, workdir: Path, fit: np.ndarray
                       ) -> tuple[np.ndarray | None, str]:
    """``soakcal calibrate`` on the ``fit`` samples and ``compensate`` of every sample, both
    raw rows in the import's layout (``--whole``): (N,3) compensated, or None and why."""
    fit_csv, all_csv = workdir / "raw_fit.csv", workdir / "raw_all.csv"
    model, comp = workdir / "raw_model.json", workdir / "raw_comp.csv"
    _write_raw(fit_csv, log, fit)
    _write_raw(all_csv, log, np.ones(log.t_s.size, bool))
    t0 = time.perf_counter()
    cal = subprocess.run([*SOAKCAL, "calibrate", str(fit_csv), "-o", str(model)],
                         capture_output=True, text=True, cwd=REPO)
    fit_s = time.perf_counter() - t0
    if cal.returncode != 0:
        return None, f"calibrate exit {cal.returncode}: {_last_line(cal.stderr)}"
    c = subprocess.run([*SOAKCAL, "compensate", str(model), str(all_csv), "-o", str(comp),
                        "--extrapolate"], capture_output=True, text=True, cwd=REPO)
    if c.returncode != 0:
        return None, f"compensate exit {c.returncode}: {_last_line(c.stderr)}"
    with comp.open() as f:
        head = f.readline().strip().split(",")
    data = np.loadtxt(comp, delimiter=",", skiprows=1)
    out = data[:, [head.index("cx"), head.index("cy"), head.index("cz")]]
    doc = json.loads(model.read_text())
    rate = (doc.get("temperature") or {}).get("rate")
    note = f"calibrate {fit_s:.1f} s; degree {(doc.get('polynomial') or {}).get('degree')}"
    return out, note + (f"; rate term over {rate['window_s']:g} s" if rate else "; no rate term")


def insample_rms_mg(log: WarmupLog, compensated_g: np.ndarray) -> np.ndarray:
    """Per axis: RMS of every full 5-s mean about their mean (mg): the whole-log figure,
    in-sample (the model saw every sample)."""
    return rms_about_mean_mg(five_s_means(log.t_s, (compensated_g,))[1][0])


def five_s_means(t_s: np.ndarray, series: tuple[np.ndarray, ...]
                 ) -> tuple[np.ndarray, list[np.ndarray]]:
    """The full 5-s means of a log (a 5-s stretch with more than 80 % of its samples): their
    indices from the log's start, and each series' (m, k) means."""
    half = np.floor((t_s - t_s[0]) / MEAN_S).astype(int)
    rate = (t_s.size - 1) / (t_s[-1] - t_s[0])
    hs = np.array([h for h in np.unique(half) if np.sum(half == h) > 0.8 * MEAN_S * rate])
    return hs, [np.array([c[half == h].mean(axis=0) for h in hs]) for c in series]


def rms_about_mean_mg(means_g: np.ndarray) -> np.ndarray:
    """Per axis: the RMS of (m, 3) means about their own mean, mg (the constant is each
    method's: gravity's projection, the firmware's ordinary offset)."""
    return np.sqrt(np.mean((means_g - means_g.mean(axis=0)) ** 2, axis=0)) * 1e3


def evaluate_whole(log: WarmupLog, workdir: Path) -> dict[str, object]:
    """``--whole``: soakcal on raw rows as a user runs it (module docstring)."""
    _, fit = blocks(log.t_s)
    res: dict[str, object] = {}
    held, res["whole_heldout_note"] = method_soakcal_raw(log, workdir, fit)
    res["whole_heldout"] = None if held is None else heldout_rms_mg(log, held).tolist()
    every, res["whole_log_note"] = method_soakcal_raw(log, workdir, np.ones(log.t_s.size, bool))
    res["whole_log_none"] = insample_rms_mg(log, log.acc_g).tolist()
    res["whole_log"] = None if every is None else insample_rms_mg(log, every).tolist()
    every_row = np.ones(log.t_s.size, bool)
    res["whole_log_px4"] = insample_rms_mg(log, method_px4(log, every_row)).tolist()
    res["whole_log_ardupilot"] = insample_rms_mg(
        log, method_ardupilot(log, every_row)[0]).tolist()
    return res


def whole_table(results: list[dict[str, object]]) -> str:
    """The ``--whole`` figures, mg x / y / z."""
    lines = ["| log | held out: 1-s rows (above) | held out: raw rows | whole log in-sample: "
             "none | PX4 method | ArduPilot tempcal | soakcal |", "|---|---|---|---|---|---|---|"]

    def fmt(v: object) -> str:
        return xyz_mg(v, missing="refused (exit 2)")

    for r in results:
        if "whole_log_none" in r:
            lines.append(f"| {r['log']} | {fmt(r['soakcal'])} | {fmt(r['whole_heldout'])} | "
                         f"{fmt(r['whole_log_none'])} | {fmt(r['whole_log_px4'])} | "
                         f"{fmt(r['whole_log_ardupilot'])} | {fmt(r['whole_log'])} |")
    return "\n".join(lines)


def _compensate_delta(model: Path, rows_csv: Path, comp: Path
                      ) -> tuple[np.ndarray | None, str]:
    """``soakcal compensate`` of ``rows_csv``: (N,3) compensated minus raw, or None and why.
    (--extrapolate: the rows are clamped to the fit span already; compensate's own
    conditioning of the temperature may still step a hair past the model's range.)"""
    c = subprocess.run([*SOAKCAL, "compensate", str(model), str(rows_csv), "-o", str(comp),
                        "--extrapolate"], capture_output=True, text=True, cwd=REPO)
    if c.returncode != 0:
        return None, f"compensate exit {c.returncode}: {_last_line(c.stderr)}"
    with comp.open() as f:
        out_rows = list(csv.DictReader(f))
    return np.array([[float(r["cx"]) - float(r["ax"]), float(r["cy"]) - float(r["ay"]),
                      float(r["cz"]) - float(r["az"])] for r in out_rows]), ""


def _last_line(text: str) -> str:
    lines = [x for x in text.strip().splitlines() if x.strip()]
    return lines[-1][:300] if lines else "(no message)"


# --- run ---------------------------------------------------------------------------------
def evaluate(log: WarmupLog, workdir: Path, fixed_degrees: bool = False,
             whole: bool = False, export: bool = False,
             as_flown: bool = False) -> dict[str, object]:
    res: dict[str, object] = {"log": log.name, "n": int(log.t_s.size),
                              "minutes": float((log.t_s[-1] - log.t_s[0]) / 60.0),
                              "temp_span_c": [float(log.temp_c.min()), float(log.temp_c.max())]}
    res["none"] = heldout_rms_mg(log, method_none(log)).tolist()
    res["px4"] = heldout_rms_mg(log, method_px4(log)).tolist()
    ap, res["ardupilot_source"] = method_ardupilot(log)
    res["ardupilot"] = heldout_rms_mg(log, ap).tolist()
    sc, res["soakcal_note"] = method_soakcal(log, workdir)
    if sc is not None:
        ok = np.all(np.isfinite(sc), axis=1)
        res["soakcal"] = heldout_rms_mg(_subset(log, ok), sc[ok]).tolist()
    else:
        res["soakcal"] = None
    res["floor"] = noise_floor_mg(log).tolist()
    if export and sc is not None:
        model_path = workdir / "model.json"
        res["rate_term"] = bool(json.loads(model_path.read_text())
                                .get("temperature", {}).get("rate"))
        from benchmarks.bench_export_quantised import ratio_interval

        folded, dropped = method_export(log, model_path), method_export(log, model_path, False)
        res["export"] = heldout_rms_mg(log, folded).tolist()
        res["export_drop"] = heldout_rms_mg(log, dropped).tolist()
        # 95 % paired bootstrap over windows of one fit and one held-out block
        peers = (method_px4(log), ap)
        res["export_over_peer_95"] = ratio_interval(log.t_s, folded, peers, 2 * BLOCK_S)
        res["export_drop_over_peer_95"] = ratio_interval(log.t_s, dropped, peers, 2 * BLOCK_S)
        res["export_over_drop_95"] = ratio_interval(log.t_s, folded, (dropped,), 2 * BLOCK_S)
        res.update(stated_vs_measured(log, model_path, sc))
    if as_flown:
        res.update(evaluate_flown(log, workdir / "model.json" if export and sc is not None
                                  else None))
    if whole:
        res.update(evaluate_whole(log, workdir))
    if fixed_degrees:
        res["fixed_degree"] = {d: heldout_rms_mg(log, method_fixed_degree(log, d)).tolist()
                               for d in range(4)}
    return res


def fixed_degree_table(results: list[dict[str, object]]) -> str:
    """Each fixed degree's figures (``--fixed-degrees``), mg x / y / z."""
    lines = ["| log | degree 0 | degree 1 | degree 2 | degree 3 |", "|---|---|---|---|---|"]
    for r in results:
        fixed = r.get("fixed_degree")
        if isinstance(fixed, dict):
            cells = " | ".join(" / ".join(f"{v:.4f}" for v in fixed[d]) for d in range(4))
            lines.append(f"| {r['log']} | {cells} |")
    return "\n".join(lines)


def export_table(results: list[dict[str, object]]) -> str:
    """The exported file's figures (``--export``), mg x / y / z, and each over the better
    peer."""
    lines = ["| log | rate term | export (rate term folded) | export drop (static) | "
             "better peer | folded ÷ peer (95 %) | static ÷ peer (95 %) | folded ÷ static "
             "(95 %) |", "|---|---|---|---|---|---|---|---|"]

    fmt = xyz_mg

    def ci(v: np.ndarray, bounds: object) -> str:
        return " / ".join(f"{x:.3f} ({a:.2f}–{b:.2f})" for x, (a, b) in zip(
            v, bounds, strict=True))  # type: ignore[call-overload]

    for r in results:
        if "export" in r:
            peer = np.minimum(r["px4"], r["ardupilot"])  # type: ignore[arg-type]
            folded_over_static = np.asarray(r["export"]) / np.asarray(r["export_drop"])
            lines.append(
                f"| {r['log']} | {'yes' if r['rate_term'] else 'no'} | {fmt(r['export'])} | "
                f"{fmt(r['export_drop'])} | {fmt(peer)} | "
                f"{ci(np.asarray(r['export']) / peer, r['export_over_peer_95'])} | "
                f"{ci(np.asarray(r['export_drop']) / peer, r['export_drop_over_peer_95'])} | "
                f"{ci(folded_over_static, r['export_over_drop_95'])} |")
    return "\n".join(lines)


def _subset(log: WarmupLog, mask: np.ndarray) -> WarmupLog:
    return WarmupLog(log.name, log.t_s[mask], log.acc_g[mask], log.temp_c[mask])


def table(results: list[dict[str, object]]) -> str:
    head = ("| log | °C span | none | PX4 method | ArduPilot tempcal | soakcal | floor |\n"
            "|---|---|---|---|---|---|---|")
    lines = [head]

    def fmt(v: object) -> str:
        return xyz_mg(v, missing="refused (exit 2)")

    for r in results:
        if "unusable" in r:
            lines.append(f"| {r['log']} | not compared: {r['unusable']} | | | | | |")
            continue
        lo, hi = r["temp_span_c"]  # type: ignore[misc]
        lines.append(f"| {r['log']} | {lo:.2f} … {hi:.2f} | {fmt(r['none'])} | {fmt(r['px4'])} "
                     f"| {fmt(r['ardupilot'])} | {fmt(r['soakcal'])} | {fmt(r['floor'])} |")
    return "\n".join(lines)


LOGS: dict[str, Callable[[], WarmupLog]] = {
    "twin": lambda: twin_log("twin"),
    "twin+rate": lambda: twin_log("twin + rate 40 µg/(°C/min)", rate_ug_per_c_per_min=40.0),
    "twin+lag": lambda: twin_log("twin + channel lag 60 s", channel_lag_s=60.0),
    "twin+rate+lag": lambda: twin_log("twin + rate + lag", rate_ug_per_c_per_min=40.0,
                                      channel_lag_s=60.0),
}


def add_log_arguments(ap: argparse.ArgumentParser) -> None:
    """The options that choose the logs (this benchmark's and bench_warmup_scatter's)."""
    ap.add_argument("--realdata", type=Path,
                    default=Path(os.environ.get("SOAKCAL_REALDATA", Path(__file__).resolve()
                                                .parents[1] / "tests/data/realdata")),
                    help="folder holding bmi270-ganesh/ (skipped when absent)")
    ap.add_argument("--log", type=Path, action="append", default=[],
                    help="a real warm-up log (PX4 .ulg, ArduPilot .bin, a CSV); repeatable")
    ap.add_argument("--log-format", choices=("ulog", "dataflash", "csv"),
                    help="soakcal import's --format for every --log (default: .ulg → ulog, "
                         ".bin → dataflash, otherwise csv)")
    ap.add_argument("--import-args", default="",
                    help="more soakcal import flags for every --log, one string (e.g. "
                         "'--columns ax=2,ay=3,az=4,temp=5 --accel-unit mg --rate-hz 500')")
    ap.add_argument("--no-twin", action="store_true",
                    help="skip the twin and BMI270 logs (only the --log files)")


def gather_logs(args: argparse.Namespace, workdir: Path
                ) -> tuple[list[WarmupLog], list[dict[str, object]]]:
    """The twin and BMI270 logs (unless ``--no-twin``) and every ``--log`` through ``soakcal
    import``; and a result row for each log that could not be used, with why."""
    logs: list[WarmupLog] = []
    unusable: list[dict[str, object]] = []
    if not args.no_twin:
        logs = [make() for make in LOGS.values()]
        bmi = args.realdata / "bmi270-ganesh"
        if bmi.is_dir():
            logs += bmi270_logs(bmi)
    for path in args.log:
        fmt = args.log_format or LOG_SUFFIX_FORMAT.get(path.suffix.lower(), "csv")
        log, said = imported_log(path, fmt, shlex.split(args.import_args), workdir)
        print(f"{path.name}: {said}", flush=True)
        if log is None:
            unusable.append({"log": f"{path.name} ({fmt})", "unusable": said})
        else:
            logs.append(log)
    return logs, unusable


def evaluate_logs(args: argparse.Namespace,
                  evaluate: Callable[[WarmupLog, Path], dict[str, Any]],
                  default: Callable[[Any], Any] | None = None) -> list[dict[str, Any]]:
    """Every log :func:`gather_logs` chooses, through ``evaluate(log, workdir)``, each
    result printed as a JSON line as it comes; the unusable logs' rows first."""
    with tempfile.TemporaryDirectory() as tmp:
        logs, results = gather_logs(args, Path(tmp))
        for log in logs:
            results.append(evaluate(log, Path(tmp)))
            print(json.dumps(results[-1], default=default), flush=True)
    return results


def write_results(out: Path | None, results: list[dict[str, Any]], text: str,
                  default: Callable[[Any], Any] | None = None) -> None:
    """``results.json`` and ``table.md`` in ``out`` (nothing when it is None)."""
    if out:
        out.mkdir(parents=True, exist_ok=True)
        (out / "results.json").write_text(json.dumps(results, indent=1, default=default))
        (out / "table.md").write_text(text + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, help="write results.json and table.md here")
    add_log_arguments(ap)
    ap.add_argument("--fixed-degrees", action="store_true",
                    help="also score each fixed degree 0..3 fitted as soakcal fits a warm-up")
    ap.add_argument("--whole", action="store_true",
                    help="also soakcal on raw rows as a user runs it: the fit blocks' "
                         "samples (held out) and the whole log (in-sample)")
    ap.add_argument("--export", action="store_true",
                    help="also the PX4 file soakcal exports, applied at each sample's reading "
                         "(the rate term folded, and dropped)")
    ap.add_argument("--as-flown", action="store_true",
                    help="also each file as its firmware flies it: PX4's 1-s poll and 1 degC "
                         "gate, ArduPilot's 1-Hz temperature filter (soakcal's with --export)")
    args = ap.parse_args(argv)
    results = evaluate_logs(args, lambda log, work: evaluate(
        log, work, args.fixed_degrees, args.whole, args.export, args.as_flown))
    text = table(results)
    if args.fixed_degrees:
        text += "\n\nFixed degrees, fitted as soakcal fits a warm-up:\n\n" + \
            fixed_degree_table(results)
    if args.export:
        text += ("\n\nThe exported PX4 file at each sample's reading (--export):\n\n"
                 + export_table(results)
                 + "\n\nThe stated RMS (file − model) against the measured (--export):\n\n"
                 + stated_table(results))
    if args.as_flown:
        text += "\n\nEach file as its firmware flies it (--as-flown):\n\n" + \
            flown_table(results)
    if args.whole:
        text += "\n\nsoakcal on raw rows as `soakcal import` writes them (--whole):\n\n" + \
            whole_table(results)
    print(text)
    for r in results:
        if "unusable" not in r:
            print(f"{r['log']}: ardupilot = {r['ardupilot_source']}; "
                  f"soakcal: {r['soakcal_note']}")
            for key in ("whole_heldout_note", "whole_log_note"):
                if key in r:
                    print(f"{r['log']}: {key}: {r[key]}")
    write_results(args.out, results, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
