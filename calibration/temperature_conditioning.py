"""Conditioning of the noisy temperature channel before it enters the thermal model (Eq. 8).

The ADXL355 temperature channel is quantised at 0.11 °C/LSB and noisy; the
chamber PV has noise of its own (``recording.md``: a reader may condition the
temperature but must say so). What we do, per temperature step:

1. robust straight line of temperature against time (two passes; the second
   drops rows more than 4 robust σ from the first line), because the die may
   still creep by a few hundredths of a degree over the ~6 min a step's
   positions take, and a line keeps that creep while averaging the noise;
2. each row gets the line's value at its time (``row_c``), the step gets the
   mean of those (``step_c``, a robust mean of the step's temperature).

A step with fewer than 3 rows or zero time span gets the median instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DESCRIPTION = (
    "per step: robust straight line of temperature vs time (rows > 4 robust sigma "
    "from the first line dropped), rows take the line's value, the step its mean"
)


@dataclass(frozen=True)
class ConditionedTemperature:
    row_c: np.ndarray  # (N,) conditioned temperature of each row
    step_c: dict[int, float]  # step index -> robust mean temperature
    step_noise_c: dict[int, float]  # step index -> robust rms scatter about the line
    rejected_rows: int
    description: str = DESCRIPTION


def condition_temperature(
    t_s: np.ndarray, temperature_c: np.ndarray, steps: np.ndarray
) -> ConditionedTemperature:
    """Robust per-step line fit of temperature vs time (see module docstring)."""
    t_s = np.asarray(t_s, float)
    temp = np.asarray(temperature_c, float)
    row_c = temp.copy()
    step_c: dict[int, float] = {}
    step_noise: dict[int, float] = {}
    rejected = 0
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
        keep = ok & (np.abs(res) <= 4.0 * sd) if sd > 0 else ok
        rejected += int(ok.sum() - keep.sum())
        if keep.sum() >= 3:
            coef = np.polyfit(tt[keep] - t0, yy[keep], 1)
        line = np.polyval(coef, tt - t0)
        row_c[idx] = line
        step_c[int(s)] = float(np.mean(line))
        step_noise[int(s)] = _robust_sd((yy - line)[keep])
    return ConditionedTemperature(row_c, step_c, step_noise, rejected)


def _robust_sd(x: np.ndarray) -> float:
    if x.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


SMOOTH_DESCRIPTION = (
    "temperature smoothed over time: robust local straight line over +/-{half:g} s, "
    "not across jumps of more than {jump:g} °C"
)


def smooth_over_time(
    t_s: np.ndarray, temperature_c: np.ndarray, window_s: float, jump_c: float = 1.0
) -> np.ndarray:
    """Each row's temperature from a local straight line over ±window_s/2 (for compensation).

    The die temperature moves slowly (time constant of minutes), so a local line
    over a few minutes keeps ramps (a cooling run, seed Fig. 11) while averaging
    the channel's noise. Segments are cut where the (3-point median filtered)
    temperature jumps by more than ``jump_c`` between rows, so readings taken at
    different soak temperatures are never mixed. Rows more than 4 robust σ off
    their local line are ignored in the fit.
    """
    t = np.asarray(t_s, float)
    y = np.asarray(temperature_c, float)
    n = y.size
    if n < 3 or window_s <= 0:
        return y.copy()
    med = np.median(np.column_stack([np.r_[y[0], y[:-1]], y, np.r_[y[1:], y[-1]]]), axis=1)
    seg = np.r_[0, np.cumsum(np.abs(np.diff(med)) > jump_c)]
    out = y.copy()
    half = 0.5 * window_s
    for s in np.unique(seg):
        idx = np.flatnonzero(seg == s)
        ts, ys = t[idx], y[idx]
        lo = np.searchsorted(ts, ts - half, side="left")
        hi = np.searchsorted(ts, ts + half, side="right")
        for j in range(idx.size):
            tt, yy = ts[lo[j] : hi[j]], ys[lo[j] : hi[j]]
            if tt.size < 3 or np.ptp(tt) <= 0:
                out[idx[j]] = float(np.median(yy))
                continue
            coef = np.polyfit(tt - ts[j], yy, 1)
            res = yy - np.polyval(coef, tt - ts[j])
            sd = _robust_sd(res)
            keep = np.abs(res) <= 4.0 * sd if sd > 0 else np.ones(tt.size, bool)
            if keep.sum() >= 3 and not keep.all():
                coef = np.polyfit(tt[keep] - ts[j], yy[keep], 1)
            out[idx[j]] = float(coef[1])
    return out
