"""Conditioning of the noisy temperature channel before it enters the thermal model (Eq. 8).

The ADXL355 temperature channel is quantised at 0.11 °C/LSB and noisy; the
chamber PV has noise of its own (``recording.md``: a reader may condition the
temperature but must say so). What we do, per temperature step:

1. robust straight line of temperature against time (two passes; the second
   drops rows more than 4 × (robust σ + the channel's quantum, if it is
   quantised) from the first line), because the die may
   still creep by a few hundredths of a degree over the ~6 min a step's
   positions take, and a line keeps that creep while averaging the noise;
   the slope is kept only where it exceeds 3 standard errors, else the rows
   get the mean (on a settled step a line's value is twice as noisy);
2. each row gets the line's value at its time (``row_c``), the step gets the
   mean of those (``step_c``, a robust mean of the step's temperature).

A step with fewer than 3 rows or zero time span gets the median instead.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration.series_memo import memo_by_value

DESCRIPTION = (
    "per step: robust straight line of temperature vs time (rows > 4 robust sigma "
    "from the first line dropped; slope kept only if > 3 standard errors, else the "
    "mean), rows take the line's value, the step its mean"
)


@dataclass(frozen=True)
class ConditionedTemperature:
    row_c: np.ndarray  # (N,) conditioned temperature of each row
    step_c: dict[int, float]  # step index -> robust mean temperature
    step_noise_c: dict[int, float]  # step index -> robust rms scatter about the line
    rejected_rows: int
    description: str = DESCRIPTION
    # (N,) the die's rate of change at each row, °C/min: the slope of its step's line (0 where
    # the slope is not significant, or the step has too few rows to draw a line)
    row_rate_c_per_min: np.ndarray | None = None


def condition_temperature(
    t_s: np.ndarray, temperature_c: np.ndarray, steps: np.ndarray
) -> ConditionedTemperature:
    """Robust per-step line fit of temperature vs time (see module docstring)."""
    t_s = np.asarray(t_s, float)
    temp = np.asarray(temperature_c, float)
    row_c = temp.copy()
    row_rate = np.zeros_like(temp)
    step_c: dict[int, float] = {}
    step_noise: dict[int, float] = {}
    rejected = 0
    quantum = channel_quantum_c(temp)
    for s in np.unique(steps):
        idx = np.flatnonzero(steps == s)
        tt, yy = t_s[idx], temp[idx]
        ok = np.isfinite(yy)
        if not ok.any():
            continue
        if idx.size < 3 or np.ptp(tt[ok]) <= 0:
            med = float(np.median(yy[ok]))
            row_c[idx] = med
            step_c[int(s)] = med
            step_noise[int(s)] = _robust_sd(yy[ok] - med)
            continue
        t0 = float(np.mean(tt))
        coef = np.polyfit(tt[ok] - t0, yy[ok], 1)
        res = yy - np.polyval(coef, tt - t0)
        sd = _robust_sd(res[ok])
        keep = ok & (np.abs(res) <= 4.0 * (sd + quantum)) if sd > 0 else ok
        rejected += int(ok.sum() - keep.sum())
        if keep.sum() >= 3:
            coef = np.polyfit(tt[keep] - t0, yy[keep], 1)
        if not _slope_significant(tt[keep], yy[keep], coef, t0):
            coef = np.array([0.0, float(np.mean(yy[keep]))])  # settled: the mean is less noisy
        line = np.polyval(coef, tt - t0)
        row_c[idx] = line
        row_rate[idx] = 60.0 * float(coef[0])
        step_c[int(s)] = float(np.mean(line))
        step_noise[int(s)] = _robust_sd((yy - line)[keep])
    return ConditionedTemperature(row_c, step_c, step_noise, rejected,
                                  row_rate_c_per_min=row_rate)


def rate_corrected_raw_g(raw_g: np.ndarray, row_rate_c_per_min: np.ndarray,
                         rate_gain_ug_per_c_per_min: np.ndarray) -> np.ndarray:
    """The raw rows less the ``temperature_rate`` effect k·dT/dt (docs/effects.md).

    While the die moves, package and board lag it and each axis reads an extra
    k·dT/dt (k in µg per °C/min, per axis, measured by the campaign from its soak
    probes: service/engine/rate_gain.py). The SFEM and thermal model (seed paper
    Eq. 1, 4–8, 12–14) describe the sensor at rest, so that term is removed from
    every row before they are fitted: otherwise a step measured while the die still
    moved carries a bias common to all its positions that the model would take for a
    temperature dependence. The rate is the conditioned line's slope of the row's step
    (``row_rate_c_per_min``): the line the thermal fit already draws through the die
    readings in time, so the two agree on how the die moved.
    """
    k_g = np.asarray(rate_gain_ug_per_c_per_min, float).reshape(1, 3) * 1e-6
    return np.asarray(raw_g, float) - np.asarray(row_rate_c_per_min, float)[:, None] * k_g


# A step's temperature slope is kept when it exceeds this many standard errors.
# Why: on a settled step the line's value at a row has twice the variance of the
# mean (averaged over the rows), so a slope that is only noise costs accuracy;
# a real creep (a die still settling) is many standard errors and is kept.
SLOPE_SIGMAS = 3.0


def _slope_significant(tt: np.ndarray, yy: np.ndarray, coef: np.ndarray, t0: float) -> bool:
    """|slope| > SLOPE_SIGMAS standard errors (ordinary LS standard error of the slope)."""
    n = tt.size
    if n < 4:
        return True  # too few rows to tell: keep the line (the old behaviour)
    sxx = float(np.sum((tt - tt.mean()) ** 2))
    if sxx <= 0:
        return False
    sd = float(np.sqrt(np.sum((yy - np.polyval(coef, tt - t0)) ** 2) / (n - 2)))
    if sd <= 0:
        return True
    return abs(float(coef[0])) > SLOPE_SIGMAS * sd / np.sqrt(sxx)


CURVE_SIGMAS = 3.0  # a plateau's curvature in time is kept beyond this many standard errors
MIN_ROWS_CURVE = 8


def curved_plateaus_c(t_s: np.ndarray, temp_c: np.ndarray, steps: np.ndarray,
            line_c: np.ndarray) -> np.ndarray:
    """The conditioned rows, a plateau's parabola in time where its curvature is significant.

    Why: ``calibrate``'s conditioning draws a line per plateau (a settling die creeps by a
    few hundredths of a degree). On a short soak the die is still on its exponential while
    the positions are read, and the line misses the curve by ±10 mK at the ends and the
    middle of every plateau, the same way on every plateau of a one-way staircase; with a
    fixed order of positions that error follows the positions. A model held fixed cannot
    absorb it: ``diagnose --against`` reads the re-measurement this way (noise-free, on the
    second generator's unchanged sensors, the line moved the shift by up to 2 σ on 10-min
    one-way recordings, docs/benchmarks.md). ``calibrate`` keeps the line.
    A parabola is kept only beyond :data:`CURVE_SIGMAS` standard errors of its curvature
    (the rows within 4 × (robust σ + quantum) of the line), so a settled or a creeping
    plateau keeps its line.
    """
    out = np.asarray(line_c, float).copy()
    quantum = channel_quantum_c(temp_c)
    for s in np.unique(steps):
        idx = np.flatnonzero(steps == s)
        tt, yy = t_s[idx], temp_c[idx]
        ok = np.isfinite(yy) & np.isfinite(out[idx])
        if ok.sum() < MIN_ROWS_CURVE or np.ptp(tt[ok]) <= 0:
            continue
        res = yy - out[idx]
        sd = _robust_sd(res[ok])
        keep = ok & (np.abs(res) <= 4.0 * (sd + quantum)) if sd > 0 else ok
        if keep.sum() < MIN_ROWS_CURVE:
            continue
        t0, span = float(np.mean(tt[keep])), float(np.ptp(tt[keep]))
        x = (tt - t0) / span
        X = np.vander(x[keep], 3)
        coef, *_ = np.linalg.lstsq(X, yy[keep], rcond=None)
        dof = int(keep.sum()) - 3
        r = yy[keep] - X @ coef
        s2 = float(r @ r) / dof
        cov = np.linalg.pinv(X.T @ X) * s2
        if cov[0, 0] > 0 and abs(coef[0]) > CURVE_SIGMAS * np.sqrt(cov[0, 0]):
            out[idx] = np.vander(x, 3) @ coef
    return out


def channel_quantum_c(temperature_c: np.ndarray) -> float:
    """The temperature channel's resolution (°C) when it is quantised, else 0.

    Why: a die channel read in steps of 0.06 °C with less noise than a step puts its
    readings a step or so off any line drawn through them, while their robust σ (the
    median deviation) can be a fraction of a step: "more than 4 robust σ" then threw
    3.3 % of honest readings away (and when nearly all readings share one level, the
    robust σ is a rounding error and every reading off that level went). The robust σ
    of quantised readings is wrong by up to a quantum, so a reading is an outlier only
    beyond 4 × (robust σ + quantum). Quantised: at most half the readings have
    distinct values; the quantum is the smallest gap between them.
    """
    y = np.asarray(temperature_c, float)
    y = y[np.isfinite(y)]
    levels = np.unique(y)
    if levels.size < 2 or levels.size > 0.5 * y.size:
        return 0.0
    gaps = np.diff(levels)
    gaps = gaps[gaps > 1e-9 * max(1.0, float(np.max(np.abs(levels))))]
    return float(np.min(gaps)) if gaps.size else 0.0


def _robust_sd(x: np.ndarray) -> float:
    if x.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


SMOOTH_DESCRIPTION = (
    "temperature smoothed over time: robust local straight line over +/-{half:g} s, "
    "not across jumps of more than {jump:g} °C"
)


def smooth_over_time(
    t_s: np.ndarray, temperature_c: np.ndarray, window_s: float, jump_c: float = 1.0,
    degree: int = 1,
) -> np.ndarray:
    """Each row's temperature from a local straight line over ±window_s/2 (for compensation).

    ``degree`` 2 fits a local parabola instead: at a ramp's turnaround the die's rate
    reverses within the window and a line there is biased by ~T''·W²/24 (0.1 °C for
    W = 300 s); a parabola is not, at ~1.5× the line's noise.

    The die temperature moves slowly (time constant of minutes), so a local line
    over a few minutes keeps ramps (a cooling run, seed Fig. 11) while averaging
    the channel's noise. Segments are cut where the (3-point median filtered)
    temperature jumps by more than ``jump_c`` between rows, so readings taken at
    different soak temperatures are never mixed. Rows more than 4 robust σ off
    their local line are ignored in the fit.
    """
    y = np.asarray(temperature_c, float)
    return smooth_many_over_time(t_s, y[None, :], window_s, jump_c, degree)[0]


def smooth_many_over_time(
    t_s: np.ndarray, temperatures_c: np.ndarray, window_s: float, jump_c: float = 1.0,
    degree: int = 1,
) -> np.ndarray:
    """:func:`smooth_over_time` of each row of ``temperatures_c`` (D, n), all read at the
    times ``t_s``: the same values as D calls (each window's fit is its own; equal to
    rounding), in one pass per set of rows that share their cuts at jumps. Why: dT/dt's
    noise is measured on draws of noise (:func:`rate_noise_c_per_min`), a warm-up fit's
    most repeated step."""
    t = np.asarray(t_s, float)
    Y = np.atleast_2d(np.asarray(temperatures_c, float))
    n = Y.shape[1]
    if n < 3 or window_s <= 0:
        return Y.copy()
    med = np.median(np.stack([np.c_[Y[:, :1], Y[:, :-1]], Y, np.c_[Y[:, 1:], Y[:, -1:]]]),
                    axis=0)
    seg = np.c_[np.zeros((Y.shape[0], 1), np.int64),
                np.cumsum(np.abs(np.diff(med, axis=1)) > jump_c, axis=1)]
    if Y.shape[0] > 1 and np.any(seg != seg[:1]):  # cut differently: by the rows' cuts
        _, group = np.unique(seg, axis=0, return_inverse=True)
        out = np.empty(Y.shape)
        for g in np.unique(group):
            rows = np.flatnonzero(group.ravel() == g)
            out[rows] = smooth_many_over_time(t, Y[rows], window_s, jump_c, degree)
        return out
    out = Y.copy()
    half = 0.5 * window_s
    quantum = np.array([channel_quantum_c(y) for y in Y])
    for s in np.unique(seg[0]):
        idx = np.flatnonzero(seg[0] == s)
        ts, ys = t[idx], Y[:, idx]
        lo = np.searchsorted(ts, ts - half, side="left")
        hi = np.searchsorted(ts, ts + half, side="right")
        if np.all(np.diff(ts) > 0) and np.all(np.isfinite(ys)):
            out[:, idx] = _local_fits(ts, ys, lo, hi, degree, quantum, half)
        else:  # repeated times or missing readings: window by window
            for d in range(Y.shape[0]):
                out[d, idx] = [_local_fit(ts[lo[j]:hi[j]], ys[d, lo[j]:hi[j]], ts[j], degree,
                                          float(quantum[d])) for j in range(idx.size)]
    return out


def _local_fit(tt: np.ndarray, yy: np.ndarray, t0: float, degree: int,
               quantum: float) -> float:
    """One row of :func:`smooth_over_time`: the robust local polynomial's value at ``t0``."""
    if tt.size < degree + 2 or np.ptp(tt) <= 0:
        return float(np.median(yy))
    coef = np.polyfit(tt - t0, yy, degree)
    res = yy - np.polyval(coef, tt - t0)
    sd = _robust_sd(res)
    keep = np.abs(res) <= 4.0 * (sd + quantum) if sd > 0 else np.ones(tt.size, bool)
    if keep.sum() >= degree + 2 and not keep.all():
        coef = np.polyfit(tt[keep] - t0, yy[keep], degree)
    return float(coef[-1])


# Rows × window entries :func:`_local_fits` takes at once (bounds its memory on long
# recordings of raw samples).
_WINDOW_CHUNK = 1 << 18


def _local_fits(ts: np.ndarray, ys: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                degree: int, quantum: np.ndarray, half_s: float) -> np.ndarray:
    """:func:`_local_fit` of every row of a run with increasing times and finite readings,
    all windows at once: each window's least squares from its moment sums, the powers of
    the time offset scaled by ``half_s`` (so the normal equations are well conditioned);
    the same fits and medians row by row, equal to them to rounding. ``ys`` (D, m): D
    series read at the times ``ts``, ``quantum`` (D,) each one's channel resolution."""
    out = np.empty(ys.shape)
    width = int(np.max(hi - lo))
    step = max(1, _WINDOW_CHUNK // max(width * ys.shape[0], 1))
    for a in range(0, ts.size, step):
        rows = np.arange(a, min(a + step, ts.size))
        out[:, rows] = _window_values(ts, ys, rows, lo[rows], hi[rows], width, degree,
                                      quantum, half_s)
    return out


def _window_values(ts: np.ndarray, ys: np.ndarray, rows: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray, width: int, degree: int, quantum: np.ndarray,
                   half_s: float) -> np.ndarray:
    """(D, rows) values of the windows of ``rows`` for each of the D series ``ys``: their
    windows are stacked series by series (each window's fit and medians are its own)."""
    n_series, n_rows = ys.shape[0], rows.size
    pos = lo[:, None] + np.arange(width)
    inside = pos < hi[:, None]
    pos = np.minimum(pos, ts.size - 1)
    yy = ys[:, pos].reshape(n_series * n_rows, width)
    inside_all = np.tile(inside, (n_series, 1))
    count = hi - lo
    # too few rows for the polynomial, or no time span: the median (times increase, so
    # the span is the last minus the first)
    value = _masked_median(yy, inside_all)
    fit_row = (count >= degree + 2) & (ts[hi - 1] - ts[lo] > 0)
    if not fit_row.any():
        return value.reshape(n_series, n_rows)
    fit = np.tile(fit_row, n_series)
    inside, yy = inside_all[fit], yy[fit]
    V1 = ((ts[pos[fit_row]] - ts[rows[fit_row], None]) / half_s)[..., None] ** np.arange(
        degree + 1)
    V = np.broadcast_to(V1, (n_series,) + V1.shape).reshape((-1,) + V1.shape[1:])
    coef = _weighted_polyfit(V, yy, inside)
    res = yy - np.einsum("rwi,ri->rw", V, coef)
    dev = np.abs(res - _masked_median(res, inside)[:, None])
    sd = 1.4826 * _masked_median(dev, inside)
    q = np.repeat(np.asarray(quantum, float), int(fit_row.sum()))
    keep = np.where((sd > 0)[:, None], np.abs(res) <= 4.0 * (sd + q)[:, None], True)
    keep &= inside
    n_keep = keep.sum(axis=1)
    again = (n_keep >= degree + 2) & (n_keep < inside.sum(axis=1))
    if again.any():
        coef[again] = _weighted_polyfit(V[again], yy[again], keep[again])
    value[fit] = coef[:, 0]
    return value.reshape(n_series, n_rows)


def _weighted_polyfit(V: np.ndarray, y: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Least-squares coefficients (increasing powers) of each row's window: ``V`` (r, w, k)
    its powers, ``y`` (r, w) its readings, ``use`` (r, w) the entries that count."""
    Vw = V * use[..., None]
    A = np.einsum("rwi,rwj->rij", Vw, V)
    b = np.einsum("rwi,rw->ri", Vw, y)
    return np.linalg.solve(A, b[..., None])[..., 0]


def _masked_median(x: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Each row's median over its ``use`` entries (``np.median``'s value: the middle one,
    or the mean of the middle two); at least one entry per row."""
    s = np.sort(np.where(use, x, np.inf), axis=1)
    c = use.sum(axis=1)
    r = np.arange(x.shape[0])
    return (s[r, (c - 1) // 2] + s[r, c // 2]) / 2.0


def temperature_rate_c_per_min(t_s: np.ndarray, temperature_c: np.ndarray,
                               window_s: float) -> np.ndarray:
    """Each row's dT/dt in °C/min: the time derivative of the robust local parabola of
    :func:`smooth_over_time` over ``window_s`` (a parabola: at a warm-up's turnaround,
    heating to cooling, a line would smear the reversal). 0 for fewer than two rows.

    Rows with gaps between them (a log's dropouts, blocks cut out of it, the alternate
    blocks a held-out test fits) are read run by run: a difference across a gap is not a
    rate. Beside a gap the window is one-sided and may hold only 3 rows, too few for a
    parabola (:func:`smooth_over_time` gives their median, flat); there a local line's
    value is used, and ``np.gradient`` differentiates within each run between gaps (a gap:
    a time step over :data:`RATE_GAP_STEPS` × the median step), never across one. Without
    that, a 10-s gap in a 2 °C/min heating read 0.18-1.19 °C/min at the rows beside it.
    A run of one row takes its neighbour run's nearest rate (no rate within it)."""
    y = np.asarray(temperature_c, float)
    return temperature_rates_c_per_min(t_s, y[None, :], window_s)[0]


def temperature_rates_c_per_min(t_s: np.ndarray, temperatures_c: np.ndarray,
                                window_s: float) -> np.ndarray:
    """:func:`temperature_rate_c_per_min` of each row of ``temperatures_c`` (D, n), all read
    at the times ``t_s``: the same values as D calls, to rounding
    (:func:`smooth_many_over_time`)."""
    t = np.asarray(t_s, float)
    Y = np.atleast_2d(np.asarray(temperatures_c, float))
    if t.size < 2 or np.ptp(t) <= 0:
        return np.zeros(Y.shape)
    parabola = smooth_many_over_time(t, Y, window_s, degree=2)
    half = 0.5 * window_s
    count = (np.searchsorted(t, t + half, side="right")
             - np.searchsorted(t, t - half, side="left"))
    smooth = parabola
    if np.any(count == 3):
        line = smooth_many_over_time(t, Y, window_s, degree=1)
        smooth = np.where(count == 3, line, parabola)
    return np.vstack([60.0 * _gradient_within_runs(row, t) for row in smooth])


# A time step longer than this many median steps is a gap: a rate is not read across it.
RATE_GAP_STEPS = 2.0


def _gradient_within_runs(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``np.gradient(y, t)`` within each run of rows between gaps (steps over
    :data:`RATE_GAP_STEPS` × the median step); a one-row run takes the nearest row's."""
    step = np.diff(t)
    cuts = np.flatnonzero(step > RATE_GAP_STEPS * np.median(step)) + 1
    out = np.full(t.size, np.nan)
    for run in np.split(np.arange(t.size), cuts):
        if run.size >= 2 and np.ptp(t[run]) > 0:
            out[run] = np.gradient(y[run], t[run])
    have = np.flatnonzero(np.isfinite(out))
    if have.size == 0:
        return np.gradient(y, t)
    if have.size < t.size:
        miss = np.flatnonzero(~np.isfinite(out))
        near = np.clip(np.searchsorted(t[have], t[miss]), 1, max(have.size - 1, 1))
        left = have[near - 1]
        right = have[np.minimum(near, have.size - 1)]
        out[miss] = out[np.where(np.abs(t[miss] - t[left]) <= np.abs(t[right] - t[miss]),
                                 left, right)]
    return out


# Windows (s) a warm-up's dT/dt may be read over (:func:`rate_window_s`), shortest first;
# each must hold at least RATE_MIN_READINGS readings for a robust parabola.
RATE_WINDOWS_S = (5.0, 10.0, 20.0, 40.0, 80.0, 120.0)
RATE_MIN_READINGS = 5
RATE_NOISE_DRAWS = 8


def temperature_noise_c(t_s: np.ndarray, temperature_c: np.ndarray) -> float:
    """Per-reading noise SD (°C) of a temperature series: the robust SD of its second
    differences over √6 (:func:`_second_difference_noise_c`), and at least quantum/√12
    when the readings are quantised (:func:`channel_quantum_c`)."""
    y = np.asarray(temperature_c, float)
    y = y[np.isfinite(y)]
    if y.size < 3:
        return 0.0
    second = y[2:] - 2.0 * y[1:-1] + y[:-2]
    return max(_second_difference_noise_c(second), channel_quantum_c(y) / math.sqrt(12.0))


def _second_difference_noise_c(second_c: np.ndarray) -> float:
    """White noise SD (°C) from second differences y[i+1] − 2·y[i] + y[i−1] of equally
    spaced readings: their robust SD over √6 (a trend that is a line over the three
    readings cancels; white noise of SD σ gives √6·σ). The one estimator of a temperature
    channel's noise: :func:`temperature_noise_c` on a series, and
    :func:`capture_temperature_noise` on the samples and sub-means inside each capture."""
    return _robust_sd(np.asarray(second_c, float)) / math.sqrt(6.0)


# A capture's temperature noise is read from its means over sub-blocks this long
# (:func:`capture_temperature_noise`): 3 or more in a capture of CAPTURE_BLOCK_S.
CAPTURE_SUB_BLOCK_S = 1.0
# Fewer second differences of sub-means than this over all captures: no estimate.
MIN_SUB_TRIPLETS = 10
# The sub-means may scatter up to this multiple of what their samples' noise predicts for
# white noise (σ_sample / √m) and still count as white: the ratio's estimate is within
# ±15 % (one SD) at 60 second differences of sub-means (20 captures of 5 s), so 1.5 is
# about 3 SD. The inclinometer's channel (issue 20) reads 2.6: its 1-s means scatter by
# 0.012 °C where 0.1 °C samples at 500 Hz predict 0.0045, and its 5-s means by 0.023 °C.
WHITE_TOLERANCE = 1.5


@dataclass(frozen=True)
class CaptureTemperatureNoise:
    """What a raw log's own samples say of its capture means' temperature noise
    (:func:`capture_temperature_noise`)."""

    per_capture_c: np.ndarray | None  # (G,) °C, None: not shown to average down as white
    sample_c: float  # one sample's noise SD (second differences within captures)
    sub_c: float  # one sub-block mean's (the same, of consecutive sub-means)
    samples_per_sub: float
    sub_block_s: float

    @property
    def white_ratio(self) -> float:
        """The sub-means' scatter over white noise's prediction, σ_sub·√m / σ_sample."""
        if self.sample_c <= 0:
            return math.inf
        return self.sub_c * math.sqrt(self.samples_per_sub) / self.sample_c

    def said(self) -> str:
        """The sentence for the fit's notes: which estimate, and why."""
        shown = (f"{self.sub_block_s:g}-s means inside the captures scatter by "
                 f"{self.sub_c:.2g} °C, {self.white_ratio:.2g}x what {self.sample_c:.2g} °C "
                 f"samples predict as white noise")
        if self.per_capture_c is None:
            return (f"from the capture means' second differences: the channel's noise does "
                    f"not average down as white noise inside a capture ({shown}; at most "
                    f"{WHITE_TOLERANCE:g}x), so a capture's own samples cannot say its mean's")
        return (f"{float(np.nanmedian(self.per_capture_c)):.2g} °C per capture mean, from "
                f"each capture's own samples ({shown})")


def capture_temperature_noise(t_s: np.ndarray, temperature_c: np.ndarray,
                              group: np.ndarray, sub_block_s: float = CAPTURE_SUB_BLOCK_S
                              ) -> CaptureTemperatureNoise | None:
    """The noise SD (°C) of each capture's mean temperature from the capture's own samples,
    where they show it; None where too few sub-blocks say anything.

    ``group``: each raw row's capture, 0 … G − 1 (rows in time order, −1: in none). The
    capture means' own second differences (:func:`temperature_noise_c` on the means) hold
    the warm-up's curvature between captures as well as their noise, and on captures 5 and
    15 s apart (the alternate 10-s blocks a held-out test fits) in a heating that turns from
    rest, the curvature is as large as the noise. Inside a capture the spacing plays no part:

    * one sample's noise σ_sample and one ``sub_block_s`` mean's σ_sub, each from second
      differences of consecutive samples or sub-means within a capture (never across two),
      pooled over the captures (:func:`_second_difference_noise_c`; the die's trend over
      three sub-blocks is a line and cancels);
    * white noise averages down: σ_sub = σ_sample / √m over m samples. Where σ_sub is within
      :data:`WHITE_TOLERANCE` of that, a capture of n samples has noise σ_sub / √(n / m),
      the sub-means taken as independent (white over the sub-block shown white below it);
    * otherwise (noise correlated beyond a sample, slower than a sub-block, or a quantised
      channel that does not dither: its readings' second differences are mostly 0) the
      samples cannot say what a capture mean's noise is, and ``per_capture_c`` is None:
      the capture means' own second differences are used, as without raw samples."""
    t = np.asarray(t_s, float)
    y = np.asarray(temperature_c, float)
    g = np.asarray(group, np.int64)
    ok = (g >= 0) & np.isfinite(y) & np.isfinite(t)
    if ok.sum() < 3:
        return None
    n_groups = int(g.max()) + 1
    if not ok.all():
        t, y, g = t[ok], y[ok], g[ok]
    start = np.full(n_groups, np.inf)
    np.minimum.at(start, g, t)
    sub = np.floor((t - start[g]) / sub_block_s).astype(np.int64)
    key = g * (int(sub.max()) + 1) + sub
    first = np.r_[0, np.flatnonzero(np.diff(key)) + 1]  # runs: rows are in time order
    counts = np.diff(np.r_[first, key.size])
    means = np.add.reduceat(y, first) / counts
    owner = g[first]
    full = counts >= 0.8 * np.median(counts)
    same = (owner[2:] == owner[:-2]) & full[2:] & full[1:-1] & full[:-2]
    second_sub = (means[2:] - 2.0 * means[1:-1] + means[:-2])[same]
    if second_sub.size < MIN_SUB_TRIPLETS:
        return None
    sample = _second_difference_noise_c(np.diff(y, 2)[g[2:] == g[:-2]])
    per_sub = float(np.median(counts[full]))
    sigma_sub = _second_difference_noise_c(second_sub)
    record = CaptureTemperatureNoise(None, sample, sigma_sub, per_sub, sub_block_s)
    if record.white_ratio > WHITE_TOLERANCE:
        return record
    n = np.bincount(g, minlength=n_groups).astype(float)
    noise = sigma_sub / np.sqrt(np.maximum(n / per_sub, 1.0))
    return CaptureTemperatureNoise(np.where(n > 0, noise, np.nan), sample, sigma_sub,
                                   per_sub, sub_block_s)


@memo_by_value
def rate_noise_c_per_min(t_s: np.ndarray, window_s: float,
                         noise_c: float | np.ndarray) -> float:
    """The noise (RMS, °C/min) :func:`temperature_rate_c_per_min` over ``window_s`` gives
    at these reading times for white temperature noise of SD ``noise_c`` (one for every
    reading, or each reading's own): measured by running it on :data:`RATE_NOISE_DRAWS`
    draws of such noise (a fixed seed), so it is the method's own, gaps and ends
    included. Computed once per distinct times, window and noise
    (:mod:`calibration.series_memo`)."""
    t = np.asarray(t_s, float)
    if np.all(np.asarray(noise_c) <= 0) or t.size < 3:
        return 0.0
    rng = np.random.default_rng(0)
    draws = np.stack([rng.normal(0.0, noise_c, t.size) for _ in range(RATE_NOISE_DRAWS)])
    sq = [np.mean(rate**2) for rate in temperature_rates_c_per_min(t, draws, window_s)]
    return float(np.sqrt(np.mean(sq)))


def rate_window_s(t_s: np.ndarray, temperature_c: np.ndarray,
                  signal_c_per_min: Callable[[np.ndarray], float], share: float,
                  other_noise_c_per_min: Callable[[float], float] | None = None,
                  noise_c: np.ndarray | None = None,
                  ) -> tuple[float, float] | None:
    """The shortest of :data:`RATE_WINDOWS_S` over which dT/dt's noise
    (:func:`rate_noise_c_per_min`, the channel's noise from :func:`temperature_noise_c`)
    is at most ``share`` of what it must resolve: ``signal_c_per_min(rate)`` (°C/min),
    called with that window's rates. A shorter window follows a warm-up's onset and
    turns without smearing them; a longer one averages a quantised channel. Returns
    (window_s, its noise in °C/min), or None when no window is both long enough to hold
    :data:`RATE_MIN_READINGS` readings, at most half the readings' time span (a rate is
    local: a window over the whole record is one parabola's slope) and quiet enough.
    ``other_noise_c_per_min``: window ↦ an error of dT/dt independent of the white noise
    (a rebuilt temperature's own, :mod:`calibration.rebuild_rate_noise`), added in
    quadrature. ``noise_c``: each reading's own noise SD where known (a capture mean's,
    from its samples: :func:`capture_temperature_noise`); None: the series' own
    (:func:`temperature_noise_c`)."""
    t = np.asarray(t_s, float)
    noise = (temperature_noise_c(t, temperature_c) if noise_c is None
             else np.nan_to_num(np.asarray(noise_c, float), nan=float(np.nanmax(noise_c))))
    span_s = float(np.ptp(t)) if t.size else 0.0
    for window in (w for w in RATE_WINDOWS_S if w <= 0.5 * span_s):
        counts = (np.searchsorted(t, t + window / 2, side="right")
                  - np.searchsorted(t, t - window / 2, side="left"))
        if t.size < RATE_MIN_READINGS or np.median(counts) < RATE_MIN_READINGS:
            continue
        rate_noise = rate_noise_c_per_min(t, window, noise)
        if other_noise_c_per_min is not None:
            rate_noise = math.hypot(rate_noise, other_noise_c_per_min(window))
        rate = temperature_rate_c_per_min(t, temperature_c, window)
        if rate_noise <= share * float(signal_c_per_min(rate)):
            return window, rate_noise
    return None


RAMP_WINDOW_S = 600.0
RAMP_DESCRIPTION = (
    "plateau rows: " + DESCRIPTION + "; continuous rows: robust local parabola of "
    "temperature vs time over +/-{half:g} s within each continuous run, the row's rate "
    "its time derivative"
)


def condition_continuous(
    t_s: np.ndarray, temperature_c: np.ndarray, steps: np.ndarray,
    window_s: float = RAMP_WINDOW_S,
) -> ConditionedTemperature:
    """Per-row temperature and rate of a recording with plateaus (``steps`` ≥ 0) and
    continuous rows (−1): plateaus as :func:`condition_temperature`, continuous runs by
    :func:`smooth_over_time` with a parabola (degree 2; the window several rows wide so a
    0.1 °C, 0.11 °C-quantised channel averages down, and short against the die's
    minutes-long time constant). A run's jump threshold is 5× its median row-to-row
    change (at least 1 °C), so a fast ramp is not cut at every row.
    """
    t = np.asarray(t_s, float)
    temp = np.asarray(temperature_c, float)
    steps = np.asarray(steps)
    on = steps >= 0
    row_c = temp.copy()
    rate = np.zeros_like(temp)
    step_c: dict[int, float] = {}
    noise: dict[int, float] = {}
    rejected = 0
    if on.any():
        cond = condition_temperature(t[on], temp[on], steps[on])
        row_c[on] = cond.row_c
        rate[on] = cond.row_rate_c_per_min if cond.row_rate_c_per_min is not None else 0.0
        step_c, noise, rejected = cond.step_c, cond.step_noise_c, cond.rejected_rows
    run = np.cumsum(np.r_[True, on[1:] != on[:-1]])
    for r in np.unique(run[~on]):
        idx = np.flatnonzero(run == r)
        jump = max(1.0, 5.0 * float(np.median(np.abs(np.diff(temp[idx]))))) \
            if idx.size > 1 else 1.0
        row_c[idx] = smooth_over_time(t[idx], temp[idx], window_s, jump_c=jump, degree=2)
        if idx.size > 1 and np.ptp(t[idx]) > 0:
            rate[idx] = 60.0 * np.gradient(row_c[idx], t[idx])
    return ConditionedTemperature(row_c, step_c, noise, rejected,
                                  RAMP_DESCRIPTION.format(half=window_s / 2),
                                  row_rate_c_per_min=rate)


# --- conditioning at compensation time (issue 11: "right by default") ----------
# Why a line and not a plain exponential average: a first-order average lags a
# ramp by its time constant (0.5 °C/min x 600 s = 5 °C); a line weighted by
# exp(-age / tau) follows a ramp with no lag, and its value at the current time
# has variance 1.25 sigma^2 / (rate * tau) (a centred boxcar of 0.8 tau).
CAUSAL_TAU_S = 600.0
CAUSAL_JUMP_C = 1.0
CAUSAL_KIND = "causal_exponential_line"
PER_STEP_KIND = "per_step_line"
CAPTURE_MEAN_KIND = "capture_mean"


def default_streaming_filter(tau_s: float = CAUSAL_TAU_S,
                             jump_c: float = CAUSAL_JUMP_C) -> dict[str, object]:
    """The causal filter a streaming consumer applies (``temperature.streaming_filter``)."""
    return {
        "kind": CAUSAL_KIND,
        "tau_s": float(tau_s),
        "jump_c": float(jump_c),
        "description": (
            f"causal straight line of temperature vs time weighted by exp(-age/{tau_s:g} s), "
            f"evaluated at the current sample (the first two samples after a restart: their "
            f"mean); restarted when two consecutive "
            f"samples differ from the estimate by more than {jump_c:g} °C (one such sample "
            f"alone is kept out of the filter as a possible spike and passed through as read)"
        ),
    }


def causal_filter(
    t_s: np.ndarray,
    temperature_c: np.ndarray,
    tau_s: float = CAUSAL_TAU_S,
    jump_c: float = CAUSAL_JUMP_C,
) -> np.ndarray:
    """Each row's temperature from the rows before it and itself only (streaming filter).

    Exponentially weighted least-squares line (weights exp(-age/tau)) kept as
    five decaying running sums, so firmware can run it in O(1) memory. NaN
    temperatures are passed through and do not update the filter.
    """
    t = np.asarray(t_s, float)
    y = np.asarray(temperature_c, float)
    out = y.copy()
    if tau_s <= 0 or y.size == 0:
        return out
    s0 = s1 = s2 = sy = sty = 0.0  # sums of w, w·dt, w·dt², w·y, w·dt·y (dt = t − t_ref)
    t_ref = t_start = t_last = 0.0
    started = False
    n_seen = 0
    pending: tuple[float, float] | None = None  # an out-of-band sample awaiting confirmation
    estimate = math.nan
    for i, (ti, yi) in enumerate(zip(t.tolist(), y.tolist(), strict=True)):
        if not math.isfinite(yi):
            continue
        if started and abs(yi - estimate) > jump_c:
            if pending is None or abs(yi - pending[1]) > jump_c:
                # maybe a spike, maybe the first row at a new soak temperature: keep it
                # out of the filter, and give the row its own reading (never a stale one)
                pending = (ti, yi)
                out[i] = yi
                continue
            started = False  # two in a row: a real jump, restart from the pending sample
            t0, y0 = pending
            s0, s1, s2, sy, sty = 1.0, 0.0, 0.0, y0, 0.0
            t_ref = t_start = t_last = t0
            n_seen = 1
            started = True
        pending = None
        if not started:
            s0, s1, s2, sy, sty = 0.0, 0.0, 0.0, 0.0, 0.0
            t_ref = t_start = t_last = ti
            n_seen = 0
            started = True
        # decay the sums to the new time, then re-reference dt to ti
        decay = math.exp(-(ti - t_last) / tau_s) if ti > t_last else 1.0
        s0 *= decay
        s1 *= decay
        s2 *= decay
        sy *= decay
        sty *= decay
        shift = ti - t_ref  # dt' = dt − shift
        s2 = s2 - 2.0 * shift * s1 + shift * shift * s0
        sty = sty - shift * sy
        s1 = s1 - shift * s0
        t_ref = t_last = ti
        s0 += 1.0
        sy += yi
        mean = sy / s0
        det = s0 * s2 - s1 * s1
        n_seen += 1
        if n_seen >= 3 and ti > t_start and det > 1e-12 * max(s0 * s2, 1e-300):
            estimate = (s2 * sy - s1 * sty) / det  # line's value at dt = 0 (now)
        else:
            estimate = mean
        out[i] = estimate
    return out


def segments_for_conditioning(
    steps: np.ndarray | None,
    setpoint_c: np.ndarray | None,
    temperature_c: np.ndarray,
    jump_c: float = CAUSAL_JUMP_C,
) -> np.ndarray | None:
    """Soak-step segments of a recording to compensate, or None if it has no steps.

    A new segment starts where the ``step`` column changes, where ``setpoint_c``
    changes, or where the (3-point median filtered) temperature jumps by more
    than ``jump_c`` -- a verification run may write one step index for several
    soak temperatures, and a line through two plateaus would be wrong.
    """
    if steps is None and setpoint_c is None:
        return None
    y = np.asarray(temperature_c, float)
    n = y.size
    change = np.zeros(n, bool)
    for col in (steps, setpoint_c):
        if col is not None:
            c = np.nan_to_num(np.asarray(col, float), nan=-1e300)
            change[1:] |= c[1:] != c[:-1]
    if n >= 2:
        yy = np.where(np.isfinite(y), y, np.nanmedian(y) if np.isfinite(y).any() else 0.0)
        med = np.median(np.column_stack([np.r_[yy[0], yy[:-1]], yy, np.r_[yy[1:], yy[-1]]]),
                        axis=1)
        change[1:] |= np.abs(np.diff(med)) > jump_c
    return np.cumsum(change)


# Below this many rows per segment (median), a recording's "steps" are not soak
# plateaus (e.g. a cooling run with a new setpoint per row): the causal filter is used.
MIN_ROWS_PER_STEP = 3


@dataclass(frozen=True)
class CompensationConditioning:
    """How ``compensate`` conditions temperature (the model file's ``temperature.compensation``).

    ``per_step``: where the recording to compensate has steps, the same robust
    line per step that calibrate used (:func:`condition_temperature`);
    otherwise (or with ``per_step`` false) the causal filter, which is also the
    filter a streaming consumer applies.
    """

    per_step: bool = True
    tau_s: float = CAUSAL_TAU_S
    jump_c: float = CAUSAL_JUMP_C
    # A warm-up model: each row at its capture's mean temperature (captures of this many
    # seconds, linear in time between them), as the model was fitted; no per-step line and
    # no long causal filter (a 600-s one lags a warm-up's curve). None for a soak model.
    capture_block_s: float | None = None

    @classmethod
    def for_warmup(cls, capture_block_s: float) -> CompensationConditioning:
        """A warm-up's conditioning: capture means; a streaming consumer's filter of about
        one capture (an exponentially weighted line does not lag a ramp)."""
        return cls(per_step=False, tau_s=capture_block_s, capture_block_s=capture_block_s)

    def to_dict(self) -> dict[str, object]:
        if self.capture_block_s is not None:
            return {
                "per_step": {"kind": PER_STEP_KIND, "enabled": False,
                             "description": "not used: a warm-up model is fitted in each "
                             "capture's own mean temperature"},
                "otherwise": {
                    "kind": CAPTURE_MEAN_KIND, "block_s": float(self.capture_block_s),
                    "description": (
                        f"each row at the mean temperature of its capture (runs of at most "
                        f"{self.capture_block_s:g} s; averaged rows are their own capture), "
                        "linear in time between capture centres: as the warm-up was fitted"),
                },
            }
        return {
            "per_step": {"kind": PER_STEP_KIND, "enabled": self.per_step,
                         "description": "where the recording has steps (step or setpoint_c "
                         "columns; also split at temperature jumps): " + DESCRIPTION},
            "otherwise": default_streaming_filter(self.tau_s, self.jump_c),
        }


def compensation_temperature(
    t_s: np.ndarray,
    temperature_c: np.ndarray,
    steps: np.ndarray | None,
    setpoint_c: np.ndarray | None,
    conditioning: CompensationConditioning = CompensationConditioning(),  # noqa: B008
) -> tuple[np.ndarray, str]:
    """Conditioned temperature per row for ``compensate``, and a one-line account of it."""
    temp = np.asarray(temperature_c, float)
    segs = (segments_for_conditioning(steps, setpoint_c, temp, conditioning.jump_c)
            if conditioning.per_step else None)
    if segs is not None and temp.size:
        sizes = np.bincount(segs)
        if float(np.median(sizes[sizes > 0])) >= MIN_ROWS_PER_STEP:
            cond = condition_temperature(t_s, temp, segs)
            return cond.row_c, (
                f"temperature conditioned per step as calibrate did ({len(cond.step_c)} "
                f"step(s), robust straight line per step)")
    out = causal_filter(t_s, temp, conditioning.tau_s, conditioning.jump_c)
    return out, (
        f"temperature conditioned by the causal filter (exponentially weighted line, "
        f"time constant {conditioning.tau_s:g} s, restart on jumps > {conditioning.jump_c:g} °C)")
