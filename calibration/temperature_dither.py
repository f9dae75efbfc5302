"""A coarse channel dithered by its own noise: the die temperature from the share of readings
one level up.

A whole-degree channel whose noise before quantisation is a good fraction of an LSB (a
board's MCU sensor, a thermistor read to 1 °C) does not step once from k to k+1: it
flickers between them for as long as the die is within about two noise SDs of the
threshold. A capture mean of its readings is then ``k`` plus the fraction read at k+1,
and that fraction is the probability a reading is beyond the threshold: with the
channel's noise SD ``σ`` (in LSB) and the die at ``z`` (level units, thresholds at
``j + ½ + φ``), the expected mean of the readings is

    g_σ(z) = z_lo + Σ_j Φ((z − (j + ½ + φ)) / σ)

(Φ the normal CDF): for σ ≳ ½ LSB g is the identity to within 1 % of an LSB (the fraction
is an unbiased estimate of where the die sits inside its LSB), for σ of 0.1–0.3 LSB it is a
softened staircase that :func:`rebuild_dithered` inverts. The steps:

1. the capture means are smoothed in time by a local quadratic (tricube weights) whose
   window is chosen by leave-one-out error among :data:`WINDOWS_S` (the readings' own
   binomial noise against the die's curvature: the data's own transition rate decides);
2. ``σ`` is the one for which the inverted trace ``g⁻¹(smoothed means)`` is smoothest
   (least RMS about a local quadratic :data:`ROUGHNESS_FACTOR` windows wide): a wrong σ
   leaves a ripple one LSB in period, the staircase's (too large a σ) or its
   over-correction (too small). Where σ ≳ ½ LSB every σ gives the same trace, and the
   smallest within :data:`FLAT_SHARE` of the least roughness is taken. The phase φ only
   shifts the whole trace (g with thresholds at j + ½ + φ is g(z − φ)): a constant the
   bias polynomial's constant absorbs, so thresholds midway between levels are taken;
0. first, whether the channel *dithers*: the flicker around its crossings, read as a
   noise SD (:func:`flicker_lsb`), at least :data:`DITHER_MIN_LSB`. Below it the flickers
   are short, the fraction carries little, and the crossing instants
   (:mod:`calibration.temperature_dequantise`) are used instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.special import ndtr

# Smoothing windows (s) tried for the capture means, shortest first (each must hold at
# least MIN_WINDOW_ROWS rows on the median to be tried).
WINDOWS_S = (10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0)
MIN_WINDOW_ROWS = 5
# The roughness of an inverted trace is its RMS about a local quadratic this many times
# the smoothing window wide (the ripple of a wrong σ is one LSB in period; the die's own
# curvature over this window is small against it).
ROUGHNESS_FACTOR = 4.0
# Candidate noise SDs (LSB).
SIGMA_GRID_LSB = tuple(np.round(np.r_[np.arange(0.03, 0.3, 0.01), np.arange(0.3, 0.81, 0.05)],
                                3).tolist())
# Where the roughness is flat (σ ≳ ½ LSB: g the identity), the smallest σ this close to
# the least roughness.
FLAT_SHARE = 0.01
# The channel dithers (the fraction of upper readings is read) from this noise SD, LSB.
DITHER_MIN_LSB = 0.15
INVERSE_POINTS_PER_LSB = 400
# The die's travel is read from the capture means smoothed over this window (s).
TRAVEL_WINDOW_S = 120.0
# A capture mean is off its level (more than 2 % of its readings elsewhere) while the die
# is within 2.05 σ of a threshold: a flicker 4.1 σ wide.
OFF_LEVEL_WIDTH_SD = 4.1


@dataclass(frozen=True)
class Dithered:
    """The rebuilt trace in level units and how it was read."""

    z: np.ndarray  # level units (the lattice's): base + lsb · z is the temperature
    sigma_lsb: float  # the channel's noise SD before quantisation, LSB
    window_s: float  # the smoothing window of the capture means
    flicker_lsb: float  # the flicker's width per crossing ÷ 4.1 (flicker_lsb)


def smoother_matrix(t: np.ndarray, window_s: float) -> sparse.csr_matrix:
    """The linear smoother of a tricube-weighted local quadratic over ±window_s/2 at each
    row of ``t`` (a row whose window holds too few rows keeps its own value).

    Row i is ``(X (XᵀWX)⁻¹ e₀) · w`` over the rows of its window (``u`` the offsets in
    half-windows, ``w = (1 − |u|³)³``, ``X = [1, u, u²]``, so ``XᵀWX`` holds the weighted
    moments Σw·uⁿ, n = 0…4). The rows are taken a block at a time (about
    :data:`SMOOTHER_BLOCK_CELLS` window cells), each window padded to the block's widest
    with cells of weight 0, which add nothing to the moments; the same matrix as one
    solve per row to rounding (tests/calibration/test_smoother_matrix.py)."""
    t = np.asarray(t, float)
    n = t.size
    lo = np.searchsorted(t, t - window_s / 2, side="left")
    hi = np.searchsorted(t, t + window_s / 2, side="right")
    half = window_s / 2
    width = int((hi - lo).max()) if n else 0
    step = max(1, SMOOTHER_BLOCK_CELLS // max(width, 1))
    rows, cols, vals = [], [], []
    for start in range(0, n, step):
        i = np.arange(start, min(start + step, n))
        a, m = lo[i], hi[i] - lo[i]
        k = np.arange(int(m.max()))
        inside = k[None, :] < m[:, None]
        j = np.where(inside, a[:, None] + k[None, :], i[:, None])
        u = np.where(inside, (t[j] - t[i][:, None]) / half, 0.0)
        w = np.where(inside, (1.0 - np.abs(u) ** 3) ** 3, 0.0)
        wu = w * u
        wu2 = wu * u
        s0, s1, s2 = w.sum(axis=1), wu.sum(axis=1), wu2.sum(axis=1)
        s3, s4 = (wu2 * u).sum(axis=1), (wu2 * u * u).sum(axis=1)
        A = np.stack([np.stack([s0, s1, s2], -1), np.stack([s1, s2, s3], -1),
                      np.stack([s2, s3, s4], -1)], -2)
        fits = m >= 4
        fits[fits] = np.linalg.cond(A[fits]) < 1e10
        c = np.zeros((i.size, 3))
        if fits.any():
            e0 = np.zeros((int(fits.sum()), 3, 1))
            e0[:, 0] = 1.0
            c[fits] = np.linalg.solve(A[fits], e0)[..., 0]
        row = (c[:, :1] + c[:, 1:2] * u + c[:, 2:] * u * u) * w
        keep = inside & fits[:, None]
        alone = i[~fits]  # too few rows, or too ill-conditioned: the row's own value
        rows += [np.repeat(i[fits], m[fits]), alone]
        cols += [j[keep], alone]
        vals += [row[keep], np.ones(alone.size)]
    if not rows:
        return sparse.csr_matrix((n, n))
    return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                     np.concatenate(cols))), shape=(n, n))


# Window cells (rows × the widest window) solved at a time: bounds the block's arrays.
SMOOTHER_BLOCK_CELLS = 200_000


def expected_level(z: np.ndarray, sigma_lsb: float) -> np.ndarray:
    """g_σ(z): the expected reading (level units) of a die at ``z`` with the thresholds
    midway between levels (module docstring; another phase φ shifts z by φ: a constant)."""
    z = np.asarray(z, float)
    j = np.arange(np.floor(z.min()) - 4, np.ceil(z.max()) + 5)
    return j[0] + ndtr((z[:, None] - (j + 0.5)[None, :]) / sigma_lsb).sum(axis=1)


def inverse_level(m: np.ndarray, sigma_lsb: float) -> np.ndarray:
    """g_σ⁻¹(m): g(z + 1) = g(z) + 1, so one period's fine grid inverts every level."""
    grid = np.linspace(-0.5, 0.5, INVERSE_POINTS_PER_LSB + 1)
    g = expected_level(grid, sigma_lsb) + 1e-9 * grid  # strictly increasing
    g = np.maximum.accumulate(g)
    k = np.round(np.asarray(m, float))
    return k + np.interp(m - k, g, grid)


def flicker_lsb(t: np.ndarray, z: np.ndarray) -> float:
    """How long the channel flickers around its crossings, as a noise SD in LSB: the share
    ``D`` of the die's travel (|d/dt| of the capture means smoothed over
    :data:`TRAVEL_WINDOW_S`, times each row's spacing) spent in rows off every level, less
    what a clean channel spends there (the row that straddles the crossing: ``r``, the
    travel-weighted mean travel of a row), over 4.1 (a row is off-level while the die is
    within Φ⁻¹(0.98) = 2.05 σ of a threshold). A channel that steps cleanly gives 0 whether
    its rows are 1 s or 5 s long; one with σ ≥ 0.25 LSB is off-level nearly always (1)."""
    from calibration.temperature_dequantise import ON_LEVEL_TOL

    span = float(np.ptp(t))
    d = float(np.median(np.diff(t)))
    window = min(TRAVEL_WINDOW_S, 0.25 * span)
    if window <= 4 * d:
        return 0.0
    travel = np.abs(np.gradient(smoother_matrix(t, window) @ z, t)) * d
    total = float(np.sum(travel))
    if total <= 0:
        return 0.0
    off = np.abs(z - np.round(z)) > ON_LEVEL_TOL
    share = float(np.sum(travel[off])) / total
    row = float(np.sum(travel ** 2)) / total
    return max(share - row, 0.0) / OFF_LEVEL_WIDTH_SD


def rebuild_dithered(t_s: np.ndarray, z: np.ndarray) -> Dithered | None:
    """The die in level units from capture means ``z`` (level units of the channel's
    lattice) at times ``t_s`` (increasing), when the channel dithers (module docstring);
    None when it does not (σ below :data:`DITHER_MIN_LSB`) or too few rows."""
    t = np.asarray(t_s, float)
    z = np.asarray(z, float)
    if t.size < 4 * MIN_WINDOW_ROWS:
        return None
    flicker = flicker_lsb(t, z)
    if flicker < DITHER_MIN_LSB:
        return None
    best: tuple[float, float, np.ndarray] | None = None
    span = float(np.ptp(t))
    for window in WINDOWS_S:
        counts = (np.searchsorted(t, t + window / 2, side="right")
                  - np.searchsorted(t, t - window / 2, side="left"))
        if np.median(counts) < MIN_WINDOW_ROWS or window > 0.25 * span:
            continue
        H = smoother_matrix(t, window)
        smooth, hat = H @ z, H.diagonal()
        ok = hat < 0.95
        if ok.sum() < 0.5 * t.size:
            continue
        loo = float(np.mean(((z - smooth)[ok] / (1.0 - hat[ok])) ** 2))
        if best is None or loo < best[0]:
            best = (loo, window, smooth)
    if best is None:
        return None
    _, window, smooth = best
    wide = smoother_matrix(t, ROUGHNESS_FACTOR * window)
    rough = []
    for sigma in SIGMA_GRID_LSB:
        inv = inverse_level(smooth, sigma)
        rough.append((float(np.sqrt(np.mean((inv - wide @ inv) ** 2))), sigma))
    least = min(r[0] for r in rough)
    # the smallest σ within FLAT_SHARE of the least roughness (σ ≳ ½ LSB: all alike)
    sigma = min(r[1] for r in rough if r[0] <= (1.0 + FLAT_SHARE) * least)
    return Dithered(inverse_level(smooth, sigma), sigma, window, flicker)
