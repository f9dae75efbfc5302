"""Where a recording has temperature plateaus, decided by physics (docs/calibration.md).

The seed's soak method (Sec. 1, Eq. 4–8) fits one SFEM per temperature step: it
assumes the sensor stands at one temperature while the table visits the step's
positions. A ramp recording (the chamber moving at 1 °C/min while the table
sweeps) has no such step: cutting its temperature column into "plateaus" invents
steps several °C wide. So a row set is a step only where treating it as one
temperature costs less than the noise of one reading:

    cost = tempco · rms(T_die − mean T_die over the set)  ≤  PLATEAU_NOISE_FRACTION · σ_row

* ``T_die`` is the temperature column seen through a straight line in time over the
  set (the channel's own noise, 0.1 °C and a 0.11 °C LSB, is not a temperature
  change): rms about the mean of a line of slope r over times t is |r|·sd(t). The
  slope is taken at its lower 2-σ bound, σ from the channel noise
  (:func:`channel_noise_c`), so channel noise alone never splits a plateau;
* ``tempco`` is :data:`TEMPCO_BOUND_UG_PER_C`, the largest output change per °C an
  ADXL355-class part shows (datasheet: offset tempco ±0.15 mg/°C max; scale
  0.01 %/°C is 0.1 mg/°C at 1 g);
* ``σ_row`` is a reading's noise, sd/√n per axis (median over the rows), or, without
  sd columns, the ADXL355's 25 µg/√Hz at ODR 62.5 Hz over √n samples.

A plateau found in the temperature column is grown with the slope at its lower
bound (noise does not end it) and then kept only if the cost at the slope's point
estimate is within the limit (a short run on a noisy channel cannot show it stood
still: its rows stay continuous, which costs nothing, they are fitted at their own
temperatures). A plateau must also carry a step fit: at least
:data:`MIN_POSITIONS_REFERENCE` (reference mode) or :data:`MIN_POSITIONS_NORM` (norm
mode) distinct positions.
Rows on no plateau are *continuous*: they are fitted at their own temperature
(:mod:`calibration.continuous`), never grouped into an invented step.

Declared steps (``step`` column, else ``setpoint_c`` changes) are checked the
same way: a declared step whose die moved too much is not a plateau, and its rows
are continuous (said in the notes). A soak step measured after a 60 min soak
costs < 1 µg against ~10 µg of noise and stays a step.

A declared step whose ``setpoint_c`` is held (one finite value over all its rows) is a
*soak*: the chamber air stood at one setpoint and the die is on the tail of its
first-order approach to it (a soakcal campaign's die still creeps 0.2–0.35 °C over a
sweep of 24 positions, after the engine's own stability decision). The step fit takes
each row at the step's conditioned temperature, a straight line in time
(:func:`calibration.temperature_conditioning.condition_temperature`), and the joint fit
evaluates every row at it; what matters is then not the creep but what that line
misses. So a soak is kept as a step when

    tempco · sqrt(max(rms(T − line)² − channel noise², 0))  ≤  PLATEAU_NOISE_FRACTION · σ_row

(:func:`line_miss_cost_ug`), and its rows are continuous otherwise (said in the notes).
An exponential tail with τ ≈ 15 min bends from its line by < 0.01 °C over a 4-min sweep:
a campaign's soaks are steps whether ``soakcal calibrate`` reads its recording or the
service fits its stored rows. A step column without a held setpoint (a ramping
setpoint, several soaks declared as one step) gets the excursion test above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibration.gate import STEP_SPARE_DOF, min_orientations
from calibration.recording import Recording

TEMPCO_BOUND_UG_PER_C = 150.0
# Temperature excursion's rms cost allowed against one reading's noise: it adds in
# quadrature, so 0.5 makes a step's rows at most √1.25 ≈ 1.12× noisier than at rest.
PLATEAU_NOISE_FRACTION = 0.5
ADXL355_SAMPLE_SD_UG = 25.0 * math.sqrt(62.5 / 2.0)  # 25 µg/√Hz over ODR/2 = 31.25 Hz
# A step fit with calibration.gate.STEP_SPARE_DOF (3) spare degrees of freedom, counted as
# the gate counts them (calibration.gate.min_orientations): 12 parameters from 3 components
# per position, or 9 from one |g| per position.
MIN_POSITIONS_REFERENCE = min_orientations("reference", STEP_SPARE_DOF)  # 5
MIN_POSITIONS_NORM = min_orientations("norm", STEP_SPARE_DOF)  # 12
SLOPE_SIGMAS = 2.0  # the slope taken at its lower bound: noise alone does not end a plateau


@dataclass(frozen=True)
class Segmentation:
    """Per-row step index (≥ 0 on a plateau/step, −1 on continuous rows) and how it was found."""

    step: np.ndarray  # (N,) int
    source: str  # "step column" | "setpoint_c" | "temperature plateaus" | "no temperature"
    row_sigma_ug: float  # the reading noise the criterion used
    channel_noise_c: float  # the temperature channel's noise per row
    notes: list[str] = field(default_factory=list)

    @property
    def continuous_rows(self) -> int:
        return int(np.sum(self.step < 0))

    @property
    def is_continuous(self) -> bool:
        """True when some rows are on no plateau (the recording needs the continuous fit)."""
        return self.continuous_rows > 0

    @property
    def plateau_ids(self) -> list[int]:
        return [int(s) for s in np.unique(self.step[self.step >= 0])]


def segment_recording(rec: Recording, orientation: np.ndarray | None = None) -> Segmentation:
    """Steps where the recording has plateaus (or declared steps that are), −1 elsewhere.

    ``orientation``: each row's distinct orientation (``gate.distinct_orientations``'
    labels, as the gate clustered them); None: clustered here (:func:`orientation_labels`).
    """
    n = len(rec)
    if not rec.has_temperature:  # one step at an unknown temperature (the soak fit's case)
        return Segmentation(np.zeros(n, int), "no temperature", math.nan, math.nan)
    t = rec.t_s
    temp = rec.temperature_c()
    sigma_ug = row_sigma_ug(rec)
    noise_c = channel_noise_c(t, temp)
    max_cost = PLATEAU_NOISE_FRACTION * sigma_ug
    need = MIN_POSITIONS_REFERENCE if rec.has_reference else MIN_POSITIONS_NORM
    orient = orientation_labels(rec) if orientation is None else orientation
    notes: list[str] = []
    if rec.has("step") or rec.has("setpoint_c"):
        declared = rec.steps()
        source = "step column" if rec.has("step") else "setpoint_c"
        step = declared.copy()
        dropped: list[str] = []
        setpoint = rec.columns.get("setpoint_c")
        dropped: list[str] = []
        bent: list[str] = []
        for s in np.unique(declared[declared >= 0]):
            idx = np.flatnonzero(declared == s)
            if setpoint is not None and held_setpoint(setpoint[idx]):  # a soak: the line
                cost = line_miss_cost_ug(t[idx], temp[idx], noise_c)
                if cost > max_cost:
                    step[idx] = -1
                    bent.append(f"{int(s)} ({np.ptp(temp[idx]):.2f} °C, {cost:.1f} µg)")
                continue
            cost = excursion_cost_ug(t[idx], temp[idx], noise_c)
            if cost > max_cost:
                step[idx] = -1
                dropped.append(f"{int(s)} ({np.ptp(temp[idx]):.2f} °C, {cost:.1f} µg)")
        if dropped:
            notes.append(
                f"{len(dropped)} declared step(s) are not temperature plateaus and are fitted "
                f"as continuous rows (temperature span, cost of one temperature vs "
                f"{max_cost:.1f} µg allowed): " + ", ".join(dropped[:8])
                + (" …" if len(dropped) > 8 else ""))
        if bent:
            notes.append(
                f"{len(bent)} soak(s) at a held setpoint are fitted as continuous rows: their "
                f"die does not follow the step's straight line in time (temperature span, "
                f"cost of what the line misses vs {max_cost:.1f} µg allowed): "
                + ", ".join(bent[:8]) + (" …" if len(bent) > 8 else ""))
    else:
        source = "temperature plateaus"
        step = find_plateaus(t, temp, noise_c, max_cost)
        for s in np.unique(step):
            idx = np.flatnonzero(step == s)
            keep = longest_stable_prefix(t[idx], temp[idx], max_cost, noise_c)
            step[idx[keep:]] = -1
    # a plateau too short to hold a step fit is continuous rows, not a step
    for s in np.unique(step[step >= 0]):
        idx = np.flatnonzero(step == s)
        if np.unique(orient[idx]).size < need:
            step[idx] = -1
    if source == "temperature plateaus":
        step = _renumber(step)
    seg = Segmentation(step, source, sigma_ug, noise_c, notes)
    notes.append(describe(seg, max_cost))
    return seg


def describe(seg: Segmentation, max_cost_ug: float) -> str:
    n = seg.step.size
    k = len(seg.plateau_ids)
    return (f"steps from {seg.source}: {k} plateau(s) with {n - seg.continuous_rows} rows, "
            f"{seg.continuous_rows} continuous row(s) (a plateau: tempco bound "
            f"{TEMPCO_BOUND_UG_PER_C:g} µg/°C × temperature excursion ≤ {max_cost_ug:.1f} µg, "
            f"half the reading noise {seg.row_sigma_ug:.1f} µg; channel noise "
            f"{seg.channel_noise_c:.3f} °C)")


def find_plateaus(t_s: np.ndarray, temp_c: np.ndarray, noise_c: float,
                  max_cost_ug: float) -> np.ndarray:
    """Greedy left-to-right runs whose :func:`excursion_cost_ug` stays ≤ ``max_cost_ug``.

    Running sums make each extension O(1); a run ends at the first row that would
    push its cost over the limit, and the next run starts there.
    """
    n = temp_c.size
    step = np.zeros(n, int)
    k, i = 0, 0
    while i < n:
        s0 = st = stt = sy = sty = 0.0
        j = i
        t0 = float(t_s[i])
        while j < n:
            dt, y = float(t_s[j]) - t0, float(temp_c[j])
            a0, at, att, ay, aty = s0 + 1, st + dt, stt + dt * dt, sy + y, sty + dt * y
            if a0 >= 2 and _cost(a0, at, att, ay, aty, noise_c) > max_cost_ug:
                break
            s0, st, stt, sy, sty = a0, at, att, ay, aty
            j += 1
        step[i:j] = k
        k += 1
        i = j
    return step


def longest_stable_prefix(t_s: np.ndarray, temp_c: np.ndarray, max_cost_ug: float,
                          noise_c: float = 0.0) -> int:
    """Rows of the longest leading part of a run whose cost is within ``max_cost_ug`` (a run
    grown with the slope's lower bound may reach into the next ramp: that end is trimmed
    off). The cost here is the larger of the line's at its slope's point estimate and the
    temperature's own rms about its mean less the channel noise (a flat start bending into
    a ramp is not a line)."""
    t = np.asarray(t_s, float) - float(t_s[0])
    y = np.asarray(temp_c, float)
    s0 = np.arange(1, t.size + 1, dtype=float)
    st, stt, sy, sty = np.cumsum(t), np.cumsum(t * t), np.cumsum(y), np.cumsum(t * y)
    sxx = stt - st * st / s0
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(sxx > 0, (sty - st * sy / s0) / sxx, 0.0)
        cost = TEMPCO_BOUND_UG_PER_C * np.abs(slope) * np.sqrt(np.clip(sxx, 0, None) / s0)
        var = np.cumsum(y * y) / s0 - (sy / s0) ** 2
        excess = TEMPCO_BOUND_UG_PER_C * np.sqrt(np.clip(var - noise_c**2, 0, None))
    cost = np.maximum(cost, excess)
    ok = np.flatnonzero(cost <= max_cost_ug)
    return int(ok[-1] + 1) if ok.size else 0


def excursion_cost_ug(t_s: np.ndarray, temp_c: np.ndarray, noise_c: float,
                      slope_sigmas: float = SLOPE_SIGMAS) -> float:
    """tempco × rms excursion of the line through (t, T) about its mean, µg (module docstring);
    the slope at its lower ``slope_sigmas`` bound."""
    t = np.asarray(t_s, float) - float(t_s[0])
    y = np.asarray(temp_c, float)
    return _cost(float(t.size), float(t.sum()), float(t @ t), float(y.sum()), float(t @ y),
                 noise_c, slope_sigmas)


def held_setpoint(setpoint_c: np.ndarray) -> bool:
    """True when a step's setpoint is one finite value over all its rows (a soak)."""
    sp = np.asarray(setpoint_c, float)
    return bool(sp.size and np.all(np.isfinite(sp)) and np.all(sp == sp[0]))


def line_miss_cost_ug(t_s: np.ndarray, temp_c: np.ndarray, noise_c: float) -> float:
    """tempco × the rms of the temperature about its straight line in time, less the
    channel noise (in quadrature), µg: what a soak's conditioning line misses."""
    t = np.asarray(t_s, float) - float(t_s[0])
    y = np.asarray(temp_c, float)
    ok = np.isfinite(y)
    if ok.sum() < 3 or np.ptp(t[ok]) <= 0:
        return 0.0
    res = y[ok] - np.polyval(np.polyfit(t[ok], y[ok], 1), t[ok])
    return TEMPCO_BOUND_UG_PER_C * math.sqrt(max(float(np.mean(res**2)) - noise_c**2, 0.0))


def _cost(s0: float, st: float, stt: float, sy: float, sty: float, noise_c: float,
          slope_sigmas: float = SLOPE_SIGMAS) -> float:
    sxx = stt - st * st / s0
    if s0 < 2 or sxx <= 0:
        return 0.0
    slope = (sty - st * sy / s0) / sxx
    slope_low = max(abs(slope) - slope_sigmas * noise_c / math.sqrt(sxx), 0.0)
    return TEMPCO_BOUND_UG_PER_C * slope_low * math.sqrt(sxx / s0)


def channel_noise_c(t_s: np.ndarray, temp_c: np.ndarray) -> float:
    """Robust rms noise of the temperature column per row, trends removed.

    Each row against the straight line through its two neighbours (exact for any
    linear trend, whatever the row spacing), scaled by that residual's own variance
    factor 1 + w₁² + w₂²; floored at the channel's quantum/√12 (quantised channels).
    """
    t = np.asarray(t_s, float)
    y = np.asarray(temp_c, float)
    if y.size < 3:
        return 0.0
    dt = t[2:] - t[:-2]
    ok = dt > 0
    w2 = np.where(ok, (t[1:-1] - t[:-2]) / np.where(ok, dt, 1.0), 0.5)
    w1 = 1.0 - w2
    e = (y[1:-1] - (w1 * y[:-2] + w2 * y[2:])) / np.sqrt(1.0 + w1**2 + w2**2)
    sd = float(1.4826 * np.median(np.abs(e - np.median(e))))
    steps = np.abs(np.diff(y))
    steps = steps[steps > 1e-9]
    quantum = float(steps.min()) if steps.size else 0.0
    return max(sd, quantum / math.sqrt(12.0))


def row_sigma_ug(rec: Recording) -> float:
    """A reading's noise per axis, µg: median sd/√n, else the ADXL355's per √n samples."""
    sig = rec.sigma_g
    if sig is not None:
        good = sig[np.isfinite(sig) & (sig > 0)]
        if good.size:
            return float(np.median(good)) * 1e6
    n = rec.columns.get("n")
    n_med = float(np.nanmedian(n)) if n is not None and np.any(np.isfinite(n)) else 1.0
    return ADXL355_SAMPLE_SD_UG / math.sqrt(max(n_med, 1.0))


def orientation_labels(rec: Recording) -> np.ndarray:
    """An orientation label per row: the readings' directions clustered into distinct
    orientations within the noise, as the gate counts them
    (:func:`calibration.gate.distinct_orientations`: never rows, never noise scatter)."""
    from calibration.gate import distinct_orientations

    return distinct_orientations(rec.raw_g, rec.sigma_g).labels


def _renumber(step: np.ndarray) -> np.ndarray:
    out = np.full_like(step, -1)
    for k, s in enumerate(np.unique(step[step >= 0])):
        out[step == s] = k
    return out
