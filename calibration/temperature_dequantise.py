"""A coarsely quantised temperature channel: the die temperature rebuilt from its steps in time.

A channel that prints whole degrees (1 °C LSB) says only which 1 °C band the die is in:
within a step the temperature is unknown to ±0.5 °C (RMS LSB/√12 = 0.29 °C), and a bias
of 1 mg/°C fitted or compensated at the step values is wrong by up to 0.5 mg whatever
the thermal model (Eq. 8). The die temperature changes continuously and slowly, so the
*instant* a reading flips from level k to k+1 is the instant the die crossed the
decision threshold between them, and those instants carry what the step values lose:

1. the channel's LSB ``q`` is read from the data (:func:`coarse_lsb_c`): the spacing of
   the levels that hold many readings; only a channel quantised at
   :data:`MIN_LSB_C` or coarser, with at least :data:`MIN_ON_LEVEL_SHARE` of its readings
   on the levels (a dithered channel averaged into capture means carries its sub-LSB
   information already), is rebuilt; any other is returned exactly as read;
2. *settled runs* are at least :data:`SETTLED_ROWS` consecutive readings on one level
   (the first and last readings count as one where they are another level); between
   two settled runs at levels a ≠ b the die crossed each threshold between them once.
   The crossing instant is the balance point of the readings between the runs: a mean
   over a row's duration ``d`` with a fraction ``u`` of its samples beyond the
   threshold puts the crossing ``u·d`` before the row's end, and readings that flicker
   between the two levels put it at the flicker's centre (the time the readings beyond
   it would fill as one block). Two runs at one level with readings of a neighbouring
   level between them are a *touch*: the die reached the threshold there. A longer
   flicker, with settled runs inside it, is a row of crossings and touches at the
   threshold, and the trace holds the threshold through it;
3. the thresholds are midway between levels: the rebuilt temperature is on the channel's
   own scale (a channel that truncates instead of rounding is off by half an LSB, a
   constant the bias polynomial's constant absorbs: a warm-up fits the bias *change*);
4. the die temperature is the monotone PCHIP through (crossing instant, threshold): it
   never leaves a band between two crossings. Where the die crosses a threshold and
   comes back (a turning point: k → k+1 → k) its extremum lies inside the step: a knot
   between the two crossings at the threshold plus h = s·D/4 (the parabola entering and
   leaving at the neighbouring crossings' mean slope s over the stay D), at most half
   an LSB (the step's value): never beyond the step the channel read. A flicker between
   two levels has slope 0 on both sides and stays at the threshold;
5. before the first crossing and after the last, the die moves on at the first (last)
   interval's slope (at least fast enough to get there by the middle of the end run)
   until it reaches its step's value, and holds it there (a rest before a warm-up is
   somewhere in its step: its value is the unbiased guess).

A reading settled on a level is never given a temperature outside that level's band.

Where the die stops or turns round inside one step the crossing instants say nothing about
its temperature beyond that step's band: such a stretch is an *unresolved span*
(:class:`UnresolvedSpan`, :func:`unresolved_spans`), reported with its times, its step,
its readings and the bound (the band between the step's two thresholds), so that a
report can say it could not be resolved (:mod:`calibration.unresolved_temperature`: why
the warm-up fit keeps those readings at the rebuilt value):

* a *peak* or *trough*: the step entered and left through the same threshold, where the
  rebuild's own estimate of the excursion (h = s·D/4, item 4, before its cap) is at least
  :data:`TURN_MIN_LSB` (a flicker at a threshold, slope 0 on both sides, is the die
  sitting at the threshold: resolved to the channel's noise);
* a *rest*: the step entered and left through different thresholds, but held
  :data:`REST_FACTOR` times longer than the neighbouring steps took to cross (a die that
  stopped in the middle of a warm-up); or the first (last) step of the log held longer
  than the first (last) crossing's slope takes to cross a whole step (the die slowed down
  or rested inside it: a rest before the heating, the plateau a warm-up settles at).

A channel whose noise *dithers* it (σ ≥ 0.1 LSB before quantisation: it flickers between
two levels for a long stretch around each crossing, and its capture means sit off the
levels most of the time) is rebuilt instead from the share of its readings one level up
(:mod:`calibration.temperature_dither`: the capture means smoothed over a window chosen by
leave-one-out error, σ read from the data, the expected-reading curve inverted); its LSB
is then read from the capture means' sums (n × mean is a sum of readings on the lattice,
:func:`summed_lattice`) where too few capture means sit on a level. The note says which
regime was used. A channel that never dithers is rebuilt from its crossings as above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import PchipInterpolator

from calibration.series_memo import memo_by_value
from calibration.temperature_dither import rebuild_dithered

# A channel quantised this coarsely (°C per LSB) or coarser is rebuilt: against the change
# of a warm-up over a capture (< 0.1 °C in 5 s, captures.CAPTURE_BLOCK_S) such a step is
# many captures wide, and its ±LSB/2 dominates a bias of 1 mg/°C. A finer channel's
# capture means (conditioning as before) are left exactly as read.
MIN_LSB_C = 0.25
# A reading within this fraction of an LSB of a level is on that level.
ON_LEVEL_TOL = 0.02
# At least this share of the readings must lie on the levels: a staircase, not a channel
# whose noise dithers it (whose capture means already resolve below the LSB).
MIN_ON_LEVEL_SHARE = 0.5
# Share of a candidate lattice's levels between the extremes that must hold readings
# (coarse_lsb_c); at most MAX_CANDIDATES spacings are tried, finest first.
MIN_LEVELS_READ = 0.8
MAX_CANDIDATES = 64
# A dithered channel's capture sums (n × mean) must lie on the lattice this often.
MIN_SUMMED_SHARE = 0.95
# A channel whose capture sums all move by one same whole number of LSB from each capture
# to the next (more often than this) is a smooth ramp sampled evenly, not a dithered
# quantised channel: its readings' noise would scatter the sums by several LSB
# (σ/√n per mean) while the die moves by a fraction of one.
MAX_UNIFORM_STEP_SHARE = 0.9
# At least this share of the readings must be exactly a level's value (_lattice): what a
# quantised channel prints, again and again.
MIN_PRINTED_SHARE = 0.25
# Consecutive readings on one level that make a settled run (between two flickers).
SETTLED_ROWS = 2
# A turn inside a step is unresolved when its estimated excursion into the step (LSB)
# reaches this: half the distance from the threshold to the step's value, where the
# rebuild's guess (the parabola of the neighbouring slopes) is no better than the bound.
TURN_MIN_LSB = 0.25
# A step crossed (entered and left through different thresholds) is a rest when held this
# many times longer than the longer of its neighbouring steps took: an exponential warm-up
# takes about twice as long for each step as for the one before (ln 3 / ln 1.67 near its
# plateau), a die that stopped much longer.
REST_FACTOR = 3.0


@dataclass(frozen=True)
class UnresolvedSpan:
    """A stretch where the rebuild cannot resolve the die temperature below its step's
    band (module docstring): the die was within ``[low_c, high_c]`` (the step's
    thresholds, on the channel's own scale: a channel that truncates reads ``level_c``
    for ``[level_c, level_c + LSB)`` instead), where exactly is not known."""

    kind: str  # "peak", "trough" or "rest"
    t_start_s: float  # the crossing that entered the step (or the log's first reading)
    t_end_s: float  # the crossing that left it (or the log's last reading)
    level_c: float  # the step's value as the channel reads it
    low_c: float
    high_c: float
    readings: int  # capture means (readings) inside the span
    samples: int  # the samples they average (readings where no ``n`` was given)

    def to_dict(self) -> dict[str, float | int | str]:
        return {"kind": self.kind, "t_start_s": self.t_start_s, "t_end_s": self.t_end_s,
                "level_c": self.level_c, "low_c": self.low_c, "high_c": self.high_c,
                "readings": self.readings, "samples": self.samples}

    def describe(self) -> str:
        """One phrase: what, when, which step, how many readings, the bound."""
        return (f"{self.kind} at {self.t_start_s:.0f}..{self.t_end_s:.0f} s in the "
                f"{self.level_c:g} °C step ({self.readings} readings): between "
                f"{self.low_c:g} and {self.high_c:g} °C")


@dataclass(frozen=True)
class Dequantised:
    """The temperature as rebuilt (or as read, when ``lsb_c`` is 0) and what was done."""

    temperature_c: np.ndarray
    lsb_c: float = 0.0  # the channel's coarse LSB; 0: not rebuilt
    transitions: int = 0  # threshold crossings the rebuild went through
    turning_points: int = 0  # k -> k+1 -> k returns, held inside their step
    dither_lsb: float = 0.0  # > 0: the dithered regime, the channel's noise SD (LSB)
    window_s: float = 0.0  # the dithered regime's smoothing window
    # where the crossings leave the temperature unknown inside a step (module docstring)
    unresolved: tuple[UnresolvedSpan, ...] = ()
    # each reading's temperature as the channel read it (the firmware's input); None when
    # not rebuilt
    read_c: np.ndarray | None = None
    # a level of the channel's lattice (°C): its readings are level_c + k · lsb_c, what the
    # firmware sees sample by sample (firmware_polynomial.reading_spread)
    level_c: float = 0.0

    def unresolved_mask(self, t_s: np.ndarray) -> np.ndarray:
        """Readings at ``t_s`` inside an unresolved span (True: the temperature is known
        only to the step's band there)."""
        t = np.asarray(t_s, float)
        mask = np.zeros(t.size, bool)
        for span in self.unresolved:
            mask |= (t >= span.t_start_s) & (t <= span.t_end_s)
        return mask

    @property
    def rebuilt(self) -> bool:
        return self.lsb_c > 0

    @property
    def regime(self) -> str:
        """"dither" (the share of upper readings), "crossings" or "as read"."""
        return "as read" if not self.rebuilt else ("dither" if self.dither_lsb > 0
                                                   else "crossings")

    def note(self) -> str | None:
        """The one line a report says about it (None: the channel was used as read)."""
        if not self.rebuilt:
            return None
        if self.dither_lsb > 0:
            return (f"temperature channel quantised at {self.lsb_c:g} °C and dithered by its "
                    f"noise (about {self.dither_lsb:.2f} LSB): die temperature rebuilt from "
                    f"the share of readings one level up (capture means smoothed over "
                    f"{self.window_s:g} s, the expected reading of a noisy quantiser "
                    f"inverted; calibrate and compensate rebuild it alike)")
        turns = (f"; {self.turning_points} turning point(s) kept inside their step"
                 if self.turning_points else "")
        return (f"temperature channel quantised at {self.lsb_c:g} °C: die temperature rebuilt "
                f"from the {self.transitions} transitions in time (monotone interpolation "
                f"through the instants the readings cross midway between levels{turns}; "
                f"calibrate and compensate rebuild it alike){self.unresolved_note()}")

    def unresolved_note(self) -> str:
        """The clause on the spans the crossings do not resolve ("" when none)."""
        if not self.unresolved:
            return ""
        shown = "; ".join(s.describe() for s in self.unresolved[:3])
        more = len(self.unresolved) - 3
        return (f"; NOT RESOLVED where the die rested or turned inside a step, its temperature "
                f"known only to that step's band: {shown}"
                + (f"; and {more} more" if more > 0 else ""))


def coarse_lsb_c(temperature_c: np.ndarray) -> float:
    """The channel's LSB (°C) when it reads a staircase of levels at least
    :data:`MIN_LSB_C` apart (module docstring, 1), else 0."""
    lattice = _lattice(np.asarray(temperature_c, float))
    return 0.0 if lattice is None else lattice[0]


def _lattice(y: np.ndarray) -> tuple[float, float] | None:
    """(LSB, a level) of a coarse staircase, or None (:func:`coarse_lsb_c`).

    Anchored at the most filled value, each spacing from it to another repeated value (at
    least :data:`MIN_LSB_C`) is a candidate LSB, finest first. The LSB is the first whose
    lattice holds at least :data:`MIN_ON_LEVEL_SHARE` of the readings and whose levels
    between the lowest and highest reading are nearly all read (:data:`MIN_LEVELS_READ`:
    a die temperature moves continuously, so it passes through every level between its
    extremes; half the LSB leaves every other level empty, twice it drops half the
    readings). LSB and level are then the median spacing of the levels' most frequent
    values and their median offset (the most filled value may be a capture mean a sample
    off its level, and so may a level's most frequent one where it was only crossed).
    """
    y = y[np.isfinite(y)]
    if y.size < 4:
        return None
    levels, counts = np.unique(np.round(y, 9), return_counts=True)
    base = float(levels[np.argmax(counts)])
    gaps = np.abs(levels[counts >= 2] - base)
    for q in np.unique(np.round(gaps[gaps >= MIN_LSB_C], 9))[:MAX_CANDIDATES]:
        z = (y - base) / q
        on = np.abs(z - np.round(z)) <= ON_LEVEL_TOL
        read = np.unique(np.round(z[on]))
        span = np.floor(z.max() + ON_LEVEL_TOL) - np.ceil(z.min() - ON_LEVEL_TOL) + 1
        if not (read.size >= 2 and np.mean(on) >= MIN_ON_LEVEL_SHARE
                and read.size >= MIN_LEVELS_READ * span):
            continue
        # each level's most frequent value (a reading, not a capture mean off it)
        zl = (levels - base) / q
        slot = np.round(zl)
        near = np.abs(zl - slot) <= ON_LEVEL_TOL
        modes = [(n, levels[near & (slot == n)][np.argmax(counts[near & (slot == n)])])
                 for n in read]
        n, v = np.array(modes).T
        # A staircase prints its levels: many readings are exactly a level's value. Near a
        # level (within ON_LEVEL_TOL·q) is not enough: a warm-up with a fine channel that
        # rested at −8.4 °C and settled at 25.8 °C after an overshoot put most capture means
        # within 0.02 of a "34.2 °C LSB" of those two rests, each a cloud of nearby values.
        printed = np.isin(np.round(y, 9), v)
        if np.mean(printed) < MIN_PRINTED_SHARE:
            continue
        q_fit = float(np.median(np.diff(v) / np.diff(n)))
        return q_fit, float(np.median(v - q_fit * n))
    return None


def dequantise(t_s: np.ndarray, temperature_c: np.ndarray,
               samples: np.ndarray | None = None) -> Dequantised:
    """:func:`dequantise_uncached`, computed once per distinct series
    (:mod:`calibration.series_memo`: refits of one log's temperatures rebuild it once);
    the arrays handed out are copies."""
    dq = _dequantise_memo(np.asarray(t_s, float), np.asarray(temperature_c, float),
                          None if samples is None else np.asarray(samples, float))
    return replace(dq, temperature_c=dq.temperature_c.copy(),
                   read_c=None if dq.read_c is None else dq.read_c.copy())


def dequantise_uncached(t_s: np.ndarray, temperature_c: np.ndarray,
                        samples: np.ndarray | None = None) -> Dequantised:
    """The die temperature rebuilt from a coarsely quantised channel's transitions in time
    (module docstring); the readings unchanged when the channel is not coarse or never
    changes level. ``t_s`` increasing; each reading covers the median spacing of the times
    (a capture mean: the fraction of its samples beyond a threshold places the crossing).
    ``samples``: each reading's number of samples (a capture mean's ``n``), which finds the
    lattice of a dithered channel whose means are off its levels."""
    t = np.asarray(t_s, float)
    y = np.asarray(temperature_c, float)
    unchanged = Dequantised(y.copy())
    lattice = _lattice(y)
    if lattice is None and samples is not None:
        lattice = summed_lattice(y, np.asarray(samples, float))
    ok = np.isfinite(y) & np.isfinite(t)
    if lattice is None or ok.sum() < 4 or np.any(np.diff(t[ok]) < 0):
        return unchanged
    q, base = lattice
    tt, yy = t[ok], y[ok]
    z = (yy - base) / q
    dith = rebuild_dithered(tt, z)
    if dith is not None:
        out = y.copy()
        out[ok] = base + q * dith.z
        return Dequantised(out, q, dither_lsb=dith.sigma_lsb, window_s=dith.window_s,
                           read_c=y.copy(), level_c=base)
    runs = _settled_runs(z)
    if len(runs) < 2:
        return unchanged
    d = float(np.median(np.diff(tt))) if tt.size > 1 else 0.0
    knots, kinds = _crossings(tt, z, runs, d)
    if not any(k != "touch" for k in kinds):
        return unchanged
    n_per = (np.ones(tt.size) if samples is None
             else np.nan_to_num(np.asarray(samples, float)[ok], nan=1.0))
    spans = tuple(
        UnresolvedSpan(kind, t0, t1, base + q * level, base + q * (level - 0.5),
                       base + q * (level + 0.5), int(np.sum(inside)), int(np.sum(n_per[inside])))
        for kind, t0, t1, level in unresolved_spans(tt, knots, kinds)
        for inside in [(tt >= t0) & (tt <= t1)])
    knots, turns = _with_turning_points(knots, kinds)
    z_rec = _evaluate(tt, knots, runs)
    # a reading settled on a level keeps a temperature inside that level's band
    for lo, hi, level in runs:
        z_rec[lo:hi] = np.clip(z_rec[lo:hi], level - 0.5, level + 0.5)
    out = y.copy()
    out[ok] = base + q * z_rec
    n_cross = sum(k != "touch" for k in kinds)
    return Dequantised(out, q, n_cross, turns, unresolved=spans, read_c=y.copy(),
                       level_c=base)


def summed_lattice(y: np.ndarray, samples: np.ndarray) -> tuple[float, float] | None:
    """(LSB, a level) of a channel whose capture means are off its levels (a dithered one):
    n × mean is a sum of n readings on the lattice, so among the captures of the most
    common n those sums differ by whole LSBs. The LSB is the most common spacing of the
    distinct sums (at least :data:`MIN_LSB_C`, and repeated: a continuous channel's sums
    are all spaced differently), accepted when nearly all the sums
    (:data:`MIN_SUMMED_SHARE`) are on its lattice and they do not move by one same number
    of LSB from each capture to the next (:data:`MAX_UNIFORM_STEP_SHARE`: an evenly
    sampled straight ramp, whose sums are spaced alike, e.g. 0.169 °C per 50-sample
    capture read as an 8.47-°C LSB). A level: the most
    repeated mean where one repeats (a capture all on one level), else the first capture's
    sum ÷ n (a level up to q/n; the channel then dithers by ≳ ½ LSB and the rebuild does
    not depend on it)."""
    ok = np.isfinite(y) & np.isfinite(samples) & (samples >= 1)
    if ok.sum() < 8:
        return None
    n_vals, n_counts = np.unique(samples[ok], return_counts=True)
    n0 = float(n_vals[np.argmax(n_counts)])
    s = y[ok][samples[ok] == n0] * n0
    if s.size < 8:
        return None
    distinct = np.unique(np.round(s, 6))
    if distinct.size < 3:
        return None
    gaps, gap_counts = np.unique(np.round(np.diff(distinct), 6), return_counts=True)
    q = float(gaps[np.argmax(gap_counts)])
    if q < MIN_LSB_C or gap_counts.max() < 3:
        return None
    k = (s - s[0]) / q
    if np.mean(np.abs(k - np.round(k)) <= ON_LEVEL_TOL) < MIN_SUMMED_SHARE:
        return None
    steps = np.diff(np.round(k))
    modal = float(np.median(steps))
    if modal != 0 and np.mean(steps == modal) > MAX_UNIFORM_STEP_SHARE:
        return None  # every capture one step further: a ramp, not a dithered lattice
    values, counts = np.unique(np.round(y[ok], 9), return_counts=True)
    base = float(values[np.argmax(counts)]) if counts.max() >= 3 else float(s[0] / n0)
    return q, base


def _settled_runs(z: np.ndarray) -> list[tuple[int, int, int]]:
    """(first row, one past the last, level) of each settled run, in time order; the first
    and last rows open and close a run of their own (rounded) level where the first or last
    settled run is another level (a warm-up that leaves its first step within a capture)."""
    level = np.round(z)
    on = np.abs(z - level) <= ON_LEVEL_TOL
    runs: list[tuple[int, int, int]] = []
    i, n = 0, z.size
    while i < n:
        if not on[i]:
            i += 1
            continue
        j = i + 1
        while j < n and on[j] and level[j] == level[i]:
            j += 1
        if j - i >= SETTLED_ROWS:
            runs.append((i, j, int(level[i])))
        i = j
    if runs and runs[0][0] > 0 and int(level[0]) != runs[0][2]:
        runs.insert(0, (0, 1, int(level[0])))
    if runs and runs[-1][1] < n and int(level[-1]) != runs[-1][2]:
        runs.append((n - 1, n, int(level[-1])))
    return runs


def _crossings(t: np.ndarray, z: np.ndarray, runs: list[tuple[int, int, int]],
               d: float) -> tuple[list[tuple[float, float]], list[str]]:
    """Knots (time, level units) at the thresholds crossed or touched between consecutive
    settled runs, and each knot's kind: "up", "down" or "touch". A flicker between two
    levels is a row of knots at their threshold: the trace holds the threshold through it
    (the die is within the channel's noise of it there)."""
    knots: list[tuple[float, float]] = []
    kinds: list[str] = []
    for (_, a_end, a), (b_start, _, b) in zip(runs[:-1], runs[1:], strict=True):
        for tc, value, kind in _region_crossings(t, z, a_end, b_start, a, b, d):
            knots.append((tc, value))
            kinds.append(kind)
    order = np.argsort([k[0] for k in knots], kind="stable")
    return [knots[i] for i in order], [kinds[i] for i in order]


def _region_crossings(t: np.ndarray, z: np.ndarray, a_end: int, b_start: int, a: int, b: int,
                      d: float) -> list[tuple[float, float, str]]:
    """The knots between a run at level ``a`` ending before row ``a_end`` and one at ``b``
    starting at row ``b_start``: (time, level units, kind)."""
    t_a, t_b = float(t[a_end - 1]), float(t[b_start])
    between = slice(a_end, b_start)
    out: list[tuple[float, float, str]] = []
    if b != a:
        sgn = 1 if b > a else -1
        n = abs(b - a)
        for j in range(1, n + 1):
            theta = a + sgn * (j - 0.5)
            if b_start > a_end:
                # balance point: the fraction of each row beyond the threshold
                u = np.clip(sgn * (z[between] - (theta - 0.5 * sgn)), 0.0, 1.0)
                tc = min(max(t_a + 0.5 * d + float(np.sum(1.0 - u)) * d, t_a), t_b)
            else:  # no reading between the runs: evenly spread over the gap
                tc = t_a + (t_b - t_a) * j / (n + 1)
            out.append((tc, theta, "up" if sgn > 0 else "down"))
        return out
    zz = z[between]
    for sgn in (1, -1):
        beyond = sgn * (zz - a) > 0.5
        if beyond.any():
            idx = np.flatnonzero(beyond) + a_end
            w = np.clip(sgn * (z[idx] - a) - 0.5, 0.0, 1.0) + 1e-12
            out.append((float(np.sum(t[idx] * w) / np.sum(w)), a + 0.5 * sgn, "touch"))
    return out


def unresolved_spans(t: np.ndarray, knots: list[tuple[float, float]], kinds: list[str]
                     ) -> list[tuple[str, float, float, float]]:
    """(kind, start s, end s, step in level units) of each stretch whose temperature the
    crossings do not resolve below its step's band (module docstring). ``knots`` and
    ``kinds`` as :func:`_crossings` gives them; touches pin the die at a threshold for an
    instant and are not crossings. The log's first and last readings bound its end steps."""
    cross = [(tc, v, 1 if kind == "up" else -1)
             for (tc, v), kind in zip(knots, kinds, strict=True) if kind != "touch"]
    if not cross:
        return []
    t_first, t_last = float(t[0]), float(t[-1])
    n = len(cross)

    def slope(i: int, j: int) -> float | None:
        """|Δθ|/Δt between crossings i and j (level units per s); None off the ends."""
        if not (0 <= i < n and 0 <= j < n) or cross[j][0] <= cross[i][0]:
            return None
        return abs(cross[j][1] - cross[i][1]) / (cross[j][0] - cross[i][0])

    # each step held between two crossings of different thresholds: how long it took
    passes = [cross[i + 1][0] - cross[i][0] if cross[i + 1][1] != cross[i][1] else None
              for i in range(n - 1)]
    typical = [p for p in passes if p is not None and p > 0]
    out: list[tuple[str, float, float, float]] = []
    for i in range(n + 1):
        b = cross[i - 1] if i > 0 else None
        e = cross[i] if i < n else None
        if b is not None and e is not None:
            level = e[1] - 0.5 * e[2]
            held = e[0] - b[0]
            if b[1] == e[1]:  # entered and left through one threshold: a turn
                slopes = [s for s in (slope(i - 2, i - 1), slope(i, i + 1)) if s is not None]
                h = float(np.mean(slopes)) * held / 4.0 if slopes else math.inf
                if h >= TURN_MIN_LSB:
                    out.append(("peak" if b[2] > 0 else "trough", b[0], e[0], level))
                continue
            near = [p for p in (passes[i - 2] if i >= 2 else None,
                                passes[i] if i < n - 1 else None) if p is not None]
            expected = max(near) if near else (float(np.median(typical)) if typical else None)
            if expected is not None and held > REST_FACTOR * expected:
                out.append(("rest", b[0], e[0], level))
        elif e is not None:  # the log's first step, left at crossing 0
            s = _end_slope(cross, 0, 1)
            if s is None or s * (e[0] - t_first) > 1.0:
                out.append(("rest", t_first, e[0], e[1] - 0.5 * e[2]))
        elif b is not None:  # the log's last step, entered at the last crossing
            s = _end_slope(cross, n - 1, -1)
            if s is None or s * (t_last - b[0]) > 1.0:
                out.append(("rest", b[0], t_last, b[1] + 0.5 * b[2]))
    return out


def _end_slope(cross: list[tuple[float, float, int]], i: int, step: int) -> float | None:
    """|slope| from crossing ``i`` to the nearest one (going by ``step``) at another
    threshold: the die's pace as it left (entered) the log's first (last) step."""
    j = i + step
    while 0 <= j < len(cross):
        if cross[j][1] != cross[i][1] and cross[j][0] != cross[i][0]:
            return abs(cross[j][1] - cross[i][1]) / abs(cross[j][0] - cross[i][0])
        j += step
    return None


def _with_turning_points(knots: list[tuple[float, float]], kinds: list[str]
                         ) -> tuple[list[tuple[float, float]], int]:
    """The knots with one inserted between each pair of crossings of one threshold in
    opposite directions (module docstring, 4); and how many were inserted."""
    out = [knots[0]]
    turns = 0
    for i in range(1, len(knots)):
        (t0, v0), (t1, v1) = knots[i - 1], knots[i]
        if v0 == v1 and {kinds[i - 1], kinds[i]} == {"up", "down"} and t1 > t0:
            slopes = []
            if i >= 2 and knots[i - 2][0] < t0:
                slopes.append(abs(v0 - knots[i - 2][1]) / (t0 - knots[i - 2][0]))
            if i + 1 < len(knots) and knots[i + 1][0] > t1:
                slopes.append(abs(knots[i + 1][1] - v1) / (knots[i + 1][0] - t1))
            h = min(0.5, float(np.mean(slopes)) * (t1 - t0) / 4.0) if slopes else 0.5
            sgn = 1.0 if kinds[i - 1] == "up" else -1.0
            if h > 0:
                out.append((0.5 * (t0 + t1), v0 + sgn * h))
                turns += 1
        out.append(knots[i])
    return out, turns


def _evaluate(t: np.ndarray, knots: list[tuple[float, float]],
              runs: list[tuple[int, int, int]]) -> np.ndarray:
    """Level units at every time: PCHIP through the knots, the ends moving on at the end
    intervals' slopes to their step's value and holding it (module docstring, 5)."""
    kt = np.array([k[0] for k in knots])
    kv = np.array([k[1] for k in knots])
    # strictly increasing knot times (coincident crossings: averaged into one knot)
    kt, inv = np.unique(kt, return_inverse=True)
    kv = np.bincount(inv, weights=kv) / np.bincount(inv)
    z = np.empty(t.size)
    inside = (t >= kt[0]) & (t <= kt[-1])
    z[inside] = PchipInterpolator(kt, kv)(t[inside]) if kt.size >= 2 else kv[0]
    (a0, a1, first_level), (b0, b1, last_level) = runs[0], runs[-1]
    # the end interval's slope; at least enough to reach the step's value by the middle of
    # the end run (a flicker's knots all at one threshold have no slope between them)
    s0 = max(_secant(kt, kv), 0.5 / max(kt[0] - 0.5 * float(t[a0] + t[a1 - 1]), 1e-9))
    s1 = max(_secant(kt[::-1], kv[::-1]),
             0.5 / max(0.5 * float(t[b0] + t[b1 - 1]) - kt[-1], 1e-9))
    before, after = t < kt[0], t > kt[-1]
    z[before] = _toward(kv[0], first_level, s0 * (kt[0] - t[before]))
    z[after] = _toward(kv[-1], last_level, s1 * (t[after] - kt[-1]))
    return z


def _secant(kt: np.ndarray, kv: np.ndarray) -> float:
    """|slope| from the first knot to the nearest one at another value (0: none)."""
    other = np.flatnonzero(kv != kv[0])
    if other.size == 0:
        return 0.0
    j = int(other[0])
    return abs(float(kv[j] - kv[0]) / float(kt[j] - kt[0]))


def _toward(start: float, level: float, moved: np.ndarray) -> np.ndarray:
    """From ``start`` toward ``level`` by ``moved`` (level units), stopping at ``level``."""
    step = np.minimum(moved, abs(level - start))
    return start + np.sign(level - start) * step


_dequantise_memo = memo_by_value(dequantise_uncached)
