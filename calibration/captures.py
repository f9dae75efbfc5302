"""The one reader of raw rows: raw samples → capture means with their sd and n.

A logger that streams every sample (PX4, ArduPilot, a 500 Hz inclinometer, the
rig's raw mode) writes thousands of rows per orientation. The rows of one
capture are not independent positions: they share the placement and the
temperature of their seconds. Eq. 1 of the seed paper is fitted to averaged
readings, so ``calibrate``, ``compensate``, the gate (:mod:`calibration.gate`)
and ``diagnose`` all read raw rows through :func:`capture_means`:

* a capture is a run of consecutive rows with the same ``step`` and ``position``
  (each where recorded), cut into blocks of at most :data:`CAPTURE_BLOCK_S`
  seconds, so that a continuous warm-up keeps its temperature resolution;
* where no ``position`` is recorded, a run is also cut where the sensor moved: rows
  whose 1-s moving variance is over :data:`MOVING_VARIANCE_FACTOR` times the still
  level are left out (the static-interval rule of the importers,
  :func:`calibration.importers.detect_static_intervals`), so that a capture never
  averages two placements of a hand-turned sensor into a direction it never had;
* its row is the mean of every numeric column, ``n`` the number of samples and
  ``sd_*`` their scatter (ddof = 1, two-pass); without a recorded ``position``, its
  ``position`` is the still stretch it came from (one placement);
* a capture whose scatter is many times the typical one was taken while the
  sensor moved (a hand turning it, the table slewing) and is left out, said in
  the notes.

Averaged recordings (``n`` > 1 or ``sd_*`` given, or one row every few seconds)
pass through unchanged, except rows whose recorded sample scatter is above what a still
accelerometer shows (:data:`calibration.importers.STILL_NOISE_CEILING_G`) and whose mean
agrees with neither neighbour's within their standard errors (:func:`_still_averaged`): a
block mean of a flight (``soakcal import --block-s``) is the mean of a moving sensor, not
an orientation, and is left out with a note, as a raw row taken while moving is; a noisy
part's blocks scatter as much sample by sample but their means stay put.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from calibration.recording import Recording

if TYPE_CHECKING:
    from calibration.temperature_conditioning import CaptureTemperatureNoise
    from calibration.temperature_dequantise import Dequantised

AXES = ("ax", "ay", "az")
SD_COLUMNS = ("sd_x", "sd_y", "sd_z")
LABELS = ("step", "position", "visit")  # whole-number labels, never averaged
# Longest capture, s: 5-s means are what a warm-up's held-out error is judged on, and the
# temperature moves by < 0.1 °C in 5 s in any warm-up a sensor survives.
CAPTURE_BLOCK_S = 5.0
# Rows closer in time than this (median) are samples, not averaged readings.
RAW_MAX_DT_S = 0.5
MIN_RAW_ROWS = 50
# A capture whose sample sd exceeds this multiple of the median capture's sd (on any
# axis) was taken while the orientation changed.
MOVING_SD_FACTOR = 20.0
# Rows whose 1-s moving variance (norm over the axes) is over this multiple of the still
# level (its 10th percentile over the log) were taken while the sensor turned. A turn by
# θ within the window scatters the readings by about θ·g/√12, so 100× the variance (10×
# the sd) finds a turn of 2° at 1 mg of noise, the resolution of distinct orientations
# (calibration.gate), and no warm-up's noise changes 10× with its temperature.
MOVING_VARIANCE_FACTOR = 100.0
MOVING_WINDOW_S = 1.0
# A still stretch shorter than this between two moves is not a capture.
MIN_STILL_S = 1.0


@dataclass
class Captures:
    """Capture means of a recording and how they were obtained."""

    recording: Recording  # one row per capture (the input itself when not raw)
    raw_rows: int  # rows read
    is_raw: bool
    row_capture: np.ndarray  # (raw_rows,) capture index of each input row, -1: left out
    notes: list[str] = field(default_factory=list)


def is_raw_samples(rec: Recording) -> bool:
    """Rows that are single samples: no ``sd_*``, ``n`` ≤ 1, and either repeated
    (step, position) labels or rows closer than :data:`RAW_MAX_DT_S` in time."""
    if any(rec.has(c) for c in SD_COLUMNS):
        return False
    n = rec.columns.get("n")
    if n is not None and np.any(np.isfinite(n) & (n > 1)):
        return False
    if len(rec) < 2:
        return False
    if rec.has("position"):
        keys = _segment_keys(rec)
        return bool(np.any(keys[1:] == keys[:-1]))
    if len(rec) < MIN_RAW_ROWS:
        return False
    dt = np.diff(rec.t_s)
    return bool(np.median(dt) < RAW_MAX_DT_S)


def capture_means(rec: Recording, *, block_s: float = CAPTURE_BLOCK_S) -> Captures:
    """The capture means of ``rec`` (see the module docstring)."""
    n_rows = len(rec)
    if not is_raw_samples(rec):
        return _still_averaged(rec)
    still = _still_rows(rec)
    keys = _segment_keys(rec)
    # a new run where the label changes or the sensor starts or stops moving
    cut = (keys[1:] != keys[:-1]) | (still[1:] != still[:-1])
    seg = np.r_[0, np.cumsum(cut)]
    t = rec.t_s
    seg_start = np.zeros(int(seg[-1]) + 1)
    first = np.r_[0, np.flatnonzero(np.diff(seg)) + 1]
    seg_start[seg[first]] = t[first]
    block = np.floor((t - seg_start[seg]) / block_s).astype(np.int64)
    key = seg.astype(np.int64) * (int(block.max()) + 1) + block
    inv = np.r_[0, np.cumsum(key[1:] != key[:-1])]  # rows are in time order: runs
    groups = int(inv[-1]) + 1
    cols = group_means(rec, inv)
    count = cols["n"]
    first = np.r_[0, np.flatnonzero(np.diff(inv)) + 1]
    for name in LABELS:  # labels are not averaged: each capture keeps its first row's
        if name in cols:
            cols[name] = rec.columns[name][first]
    if "position" not in cols:
        # the placement each capture was averaged from: captures of one still stretch are
        # one position (static interval), as an import's interval is, so that a held-out
        # figure leaves out a placement, not 5 s of it (calibration.holdout)
        cols["position"] = seg[first].astype(float)
    moving = np.bincount(inv, weights=(~still).astype(float), minlength=groups) > 0
    keep = _steady(cols, np.where(moving, 0.0, count)) & ~moving
    notes = [f"raw samples: {n_rows} rows read as {groups - int(moving.sum())} capture means "
             f"(runs of the same step and position, at most {block_s:g} s each; sd and n of "
             f"their samples)"]
    if moving.any():
        notes.append(f"{int(np.sum(~still))} row(s) left out: the sensor was moving (1-s "
                     f"moving variance over {MOVING_VARIANCE_FACTOR:g}x the still level)")
    if not (keep | moving).all():
        notes.append(f"{int(np.sum(~keep & ~moving))} capture(s) left out: their sample scatter "
                     f"is over "
                     f"{MOVING_SD_FACTOR:g}x the typical one (the sensor was moving)")
    kept = {k: v[keep] for k, v in cols.items()}
    if not rec.has("position"):  # placements numbered 0, 1, … over the kept captures
        kept["position"] = np.unique(kept["position"], return_inverse=True)[1].astype(float)
    out = Recording.from_columns(kept, path=rec.path)
    out.notes.extend(rec.notes)
    new_index = np.where(keep, np.cumsum(keep) - 1, -1)
    return Captures(out, n_rows, True, new_index[inv], notes)


def own_temperature_noise(rec: Recording, caps: Captures) -> CaptureTemperatureNoise | None:
    """What the raw samples of ``caps``' captures say of each capture mean's temperature
    noise (:func:`calibration.temperature_conditioning.capture_temperature_noise`, read in
    the capture means' temperature source); None where ``rec`` is not raw samples, has no
    temperature or too few sub-blocks. Read only where a fit needs it (a warm-up's rate
    check), not by every reader of raw rows: at 1 M readings it is another 60 MB."""
    from calibration.temperature_conditioning import capture_temperature_noise

    if not caps.is_raw or not rec.has_temperature or not np.any(caps.row_capture >= 0):
        return None
    return capture_temperature_noise(rec.t_s, rec.temperature_c(), caps.row_capture)


def group_means(rec: Recording, group: np.ndarray) -> dict[str, np.ndarray]:
    """Columns of one row per group (``group``: 0..G-1 per row): means, sample sd, count.

    Every numeric column is averaged over the group's finite cells (NaN where none);
    ``n`` is the number of rows and ``sd_*`` the scatter of ``ax ay az`` (ddof = 1,
    two-pass: the µg scatter of ~1 g values is lost in Σx² − n·x̄²; NaN for one row).
    The aggregation of every reader of raw samples (diagnose's per-position means too).
    """
    inv = np.asarray(group, np.int64)
    groups = int(inv.max()) + 1 if inv.size else 0
    count = np.bincount(inv, minlength=groups).astype(float)
    cols: dict[str, np.ndarray] = {}
    for name, v in rec.columns.items():
        if name == "n":
            continue
        ok = np.isfinite(v)
        k = np.bincount(inv[ok], minlength=groups)
        total = np.bincount(inv[ok], weights=v[ok], minlength=groups)
        with np.errstate(invalid="ignore", divide="ignore"):
            cols[name] = np.where(k > 0, total / np.maximum(k, 1), np.nan)
    for axis, sd in zip(AXES, SD_COLUMNS, strict=True):
        d = rec.columns[axis] - cols[axis][inv]
        ss = np.bincount(inv, weights=d * d, minlength=groups)
        with np.errstate(invalid="ignore", divide="ignore"):
            cols[sd] = np.where(count > 1, np.sqrt(ss / np.maximum(count - 1, 1)), np.nan)
    cols["n"] = count
    return cols


def placed_samples(rec: Recording, caps: Captures) -> Recording:
    """The raw rows ``caps`` kept, each labelled with its capture's ``position`` (the
    still stretch it belongs to): for a reader that averages per (step, position) itself
    (``diagnose``'s capture model), the same placements ``calibrate`` fits. Recordings
    that label their positions are returned unchanged; an averaged recording as
    :func:`capture_means` kept it."""
    if not caps.is_raw:  # itself, or less the rows averaged while moving
        return caps.recording
    if rec.has("position"):
        return rec
    kept = caps.row_capture >= 0
    cols = {k: v[kept] for k, v in rec.columns.items()}
    cols["position"] = caps.recording.columns["position"][caps.row_capture[kept]]
    out = Recording.from_columns(cols, path=rec.path)
    out.notes.extend(rec.notes)
    return out


def warmup_captures(means: Recording) -> tuple[Recording, str | None]:
    """:func:`warmup_rebuild` with the line that says what was done (None: nothing)."""
    out, dq = warmup_rebuild(means)
    return out, (None if dq is None else dq.note())


def warmup_rebuild(means: Recording) -> tuple[Recording, Dequantised | None]:
    """The capture means a warm-up is fitted and compensated in: their temperature rebuilt
    from the steps' transitions in time where the channel is coarsely quantised
    (:func:`calibration.temperature_dequantise.dequantise`), with the line that says so;
    otherwise ``means`` itself and None. The one place the warm-up's fit, its held-out and
    rate checks (:mod:`calibration.warmup`) and ``compensate`` read their temperature."""
    from calibration.temperature_dequantise import dequantise

    if not means.has_temperature or len(means) < 4:
        return means, None
    dq = dequantise(means.t_s, means.temperature_c(), means.columns.get("n"))
    if not dq.rebuilt:
        return means, None
    cols = dict(means.columns)
    cols[means.temperature_source] = dq.temperature_c
    out = Recording.from_columns(cols, path=means.path)
    note = dq.note()
    out.notes.extend(list(means.notes) + ([note] if note else []))
    return out, dq


def capture_temperature_c(rec: Recording, caps: Captures,
                          means: Recording | None = None) -> np.ndarray:
    """Each raw row's temperature read from the capture means (``means``: default
    ``caps.recording``; a warm-up's :func:`warmup_captures`): linear in time between capture
    centres (a quantised or noisy channel averaged over each capture). Rows that are not
    raw samples are their own captures: ``means``' temperature where given, else their own."""
    means = caps.recording if means is None else means
    if not caps.is_raw:
        return means.temperature_c() if means is not caps.recording else rec.temperature_c()
    if not means.has_temperature:
        return rec.temperature_c()
    return np.interp(rec.t_s, means.t_s, means.temperature_c())


# Two neighbouring averaged rows of a still sensor agree within this many standard errors
# per axis (plus what the steepest plausible bias tempco turns between their temperatures).
NEIGHBOUR_AGREE_SE = 4.0


def _still_averaged(rec: Recording) -> Captures:
    """An averaged recording as its own captures, less the rows taken while the sensor
    moved or vibrated (module docstring): a recorded sample sd on some axis above
    :data:`calibration.importers.STILL_NOISE_CEILING_G`, and a mean that agrees with
    neither neighbour's (:func:`_agrees_with_a_neighbour`). The second condition is the
    block-scale form of the importers' low-pass (:data:`calibration.importers.
    STILL_LOWPASS_S`): white noise of a noisy part scatters the samples, not the means."""
    from calibration.importers import (  # importers read recordings
        STILL_LOWPASS_S,
        STILL_NOISE_CEILING_G,
    )

    n_rows = len(rec)
    if not all(rec.has(c) for c in SD_COLUMNS):
        return Captures(rec, n_rows, False, np.arange(n_rows))
    sd = np.column_stack([rec.columns[c] for c in SD_COLUMNS])
    noisy = (np.isfinite(sd) & (sd > STILL_NOISE_CEILING_G)).any(axis=1)
    moving = noisy & ~(_white_means_under_ceiling(rec, sd) & _agrees_with_a_neighbour(rec, sd))
    notes = []
    if (noisy & ~moving).any():
        notes.append(
            f"{int(np.sum(noisy & ~moving))} row(s) scatter sample by sample above the "
            f"{1e3 * STILL_NOISE_CEILING_G:g} mg a still accelerometer's noise usually stays "
            f"under (up to {1e3 * float(np.nanmax(sd[noisy & ~moving])):.0f} mg), but as white "
            f"noise their {STILL_LOWPASS_S:g}-s means would stay under it and their means agree "
            f"with a neighbour's within {NEIGHBOUR_AGREE_SE:g} standard errors: kept as still "
            f"(a noisy part)")
    if not moving.any():
        return Captures(rec, n_rows, False, np.arange(n_rows), notes)
    keep = ~moving
    notes.append(f"{int(moving.sum())} of {n_rows} row(s) left out: their sample scatter "
                 f"(up to {1e3 * float(np.nanmax(sd[moving])):.0f} mg) is above the "
                 f"{1e3 * STILL_NOISE_CEILING_G:g} mg a still accelerometer stays under and "
                 f"their means agree with neither neighbour's: the sensor moved or vibrated "
                 f"while they were averaged")
    return Captures(rec.subset(keep), n_rows, False,
                    np.where(keep, np.cumsum(keep) - 1, -1), notes)


def _white_means_under_ceiling(rec: Recording, sd: np.ndarray) -> np.ndarray:
    """(N,) rows whose sample sd, were it white noise, would scatter the importers'
    :data:`calibration.importers.STILL_LOWPASS_S` means under the still ceiling:
    sd / √(rate · span) on every axis, the rate no higher than ``n`` over the row's
    spacing from its nearest neighbour in time (a row spans at most that; a lower rate is
    the cautious side). A flight's 40-130 mg at 50 Hz stays above (27 mg); a noisy
    inclinometer's 18 mg at 500 Hz is 2.5 mg."""
    from calibration.importers import STILL_LOWPASS_S, STILL_NOISE_CEILING_G

    if len(rec) < 2 or not rec.has("n"):
        return np.zeros(len(rec), bool)
    gap = np.diff(rec.t_s)  # rows are in time order (recording.validate)
    spacing = np.minimum(np.r_[np.inf, gap], np.r_[gap, np.inf])
    rate_hz = rec.columns["n"] / np.where(spacing > 0, spacing, np.inf)
    per_mean = np.sqrt(np.maximum(rate_hz * STILL_LOWPASS_S, 1.0))
    return np.all(sd / per_mean[:, None] <= STILL_NOISE_CEILING_G, axis=1)


def _agrees_with_a_neighbour(rec: Recording, sd: np.ndarray) -> np.ndarray:
    """(N,) rows whose mean agrees, on every axis, with the previous or the next row's
    (in time) within :data:`NEIGHBOUR_AGREE_SE` standard errors of their difference plus
    the bias change a tempco of :data:`calibration.gate.BIAS_TEMPCO_MAX_G_PER_C` makes
    between their temperatures. Rows without ``n`` never agree (no standard error)."""
    from calibration.gate import BIAS_TEMPCO_MAX_G_PER_C

    n = len(rec)
    if n < 2 or not rec.has("n"):
        return np.zeros(n, bool)
    # rows are in time order (recording.validate): neighbours are adjacent rows
    se2 = sd**2 / np.maximum(rec.columns["n"], 1.0)[:, None]
    temp = rec.temperature_c() if rec.has_temperature else np.zeros(n)
    d_temp = np.nan_to_num(np.abs(np.diff(temp)), nan=0.0)
    bound = (NEIGHBOUR_AGREE_SE * np.sqrt(se2[1:] + se2[:-1])
             + BIAS_TEMPCO_MAX_G_PER_C * d_temp[:, None])
    pair = np.all(np.abs(np.diff(rec.raw_g, axis=0)) <= bound, axis=1)  # row i with i+1
    return np.r_[False, pair] | np.r_[pair, False]


def _still_rows(rec: Recording) -> np.ndarray:
    """Rows not taken while the sensor moved (module docstring). Rows labelled with a
    ``position`` are the placement the label says: all still here."""
    from calibration.importers import detect_static_intervals  # importers read recordings

    n = len(rec)
    if rec.has("position") or n < 3:
        return np.ones(n, bool)
    still = np.zeros(n, bool)
    for start, end in detect_static_intervals(
            rec.t_s, rec.raw_g, window_s=MOVING_WINDOW_S, threshold=MOVING_VARIANCE_FACTOR,
            min_duration_s=MIN_STILL_S):
        still[start:end] = True
    return still


def _segment_keys(rec: Recording) -> np.ndarray:
    """One integer per row: its (step, position) label where recorded, else 0."""
    key = np.zeros(len(rec), np.int64)
    for name in ("step", "position"):
        if name in rec.columns:
            v = np.nan_to_num(rec.columns[name], nan=-1.0).astype(np.int64)
            key = key * (int(v.max(initial=0)) + 2) + (v + 1)
    return key


def _steady(cols: dict[str, np.ndarray], count: np.ndarray) -> np.ndarray:
    """Captures not taken while moving (see :data:`MOVING_SD_FACTOR`)."""
    sd = np.column_stack([cols[c] for c in SD_COLUMNS])
    ok = np.isfinite(sd).all(axis=1) & (count > 2)
    if ok.sum() < 3:
        return np.ones(count.size, bool)
    typical = np.median(sd[ok], axis=0)
    typical = np.where(typical > 0, typical, np.max(typical))
    if not np.all(typical > 0):
        return np.ones(count.size, bool)
    return ~(np.isfinite(sd) & (sd > MOVING_SD_FACTOR * typical)).any(axis=1)
