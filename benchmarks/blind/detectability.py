"""Minimum detectable size of an effect under a protocol (``docs/blind-benchmark.md``).

The base model, linearised: per axis ``raw_i = Σ_j B_ij(T) ref_j + b_i(T)`` with
every entry cubic in the recorded temperature (first-order equivalent of the
12-parameter SFEM with cubic parameters: A = M·C·S spans all 3×3 matrices).
An effect's noise-free signature ``x`` (its change of the output relative to
the base model at the recorded temperature) is whitened by the reading noise
σ and projected off the base columns; the non-centrality is
``λ = ‖(I − P_base) x / σ‖``. The effect is "just detectable" when a
``df``-parameter test at family level α = 0.01, Bonferroni-split over the
catalogue's candidates, has 50 % power: λ ≈ 3.4 for one parameter.

Effects that sit on a few unknown readings (``outlier``, temperature-channel
glitches) are different: *which* readings is itself a free parameter that no
test can know in advance, so any detector must scan all N readings and pay
the look-elsewhere factor N, and it can only test one reading's signal at a
time. For them the criterion is a per-reading test (``df_row`` dof, level
α/(N_candidates·N)) detecting at least one disturbed reading with probability
50 %: :func:`minimum_detectable_rows` (docs/blind-benchmark.md).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import optimize, stats

N_CANDIDATES = 15  # catalogue ids a diagnoser searches over (effects.md)
ALPHA = 0.01
POWER = 0.5


def base_design(ref_g: np.ndarray, temp_c: np.ndarray, degree: int = 3) -> np.ndarray:
    """Columns of the linearised base model for one axis: [ref_x, ref_y, ref_z, 1] ⊗ T⁰..T^deg."""
    u = (np.asarray(temp_c, float) - 25.0) / 50.0
    powers = np.column_stack([u**j for j in range(degree + 1)])
    inputs = np.column_stack([np.asarray(ref_g, float), np.ones(len(u))])
    return np.einsum("ni,nj->nij", inputs, powers).reshape(len(u), 4 * (degree + 1))


def noncentrality(x_g: np.ndarray, ref_g: np.ndarray, temp_c: np.ndarray,
                  sigma_g: np.ndarray) -> float:
    """λ = ‖(I − P_base) x/σ‖ summed over axes; ``x_g`` (N,3) g, ``sigma_g`` (N,) or (N,3) g."""
    X = base_design(ref_g, temp_c)
    sig = np.broadcast_to(np.asarray(sigma_g, float).reshape(len(X), -1), x_g.shape)
    lam2 = 0.0
    for i in range(3):
        w = 1.0 / sig[:, i]
        Xw, xw = X * w[:, None], x_g[:, i] * w
        coef, *_ = np.linalg.lstsq(Xw, xw, rcond=None)
        r = xw - Xw @ coef
        lam2 += float(r @ r)
    return float(np.sqrt(lam2))


def threshold(df: int = 1, alpha: float = ALPHA, n_candidates: int = N_CANDIDATES,
              power: float = POWER) -> float:
    """λ at which a df-dof χ² test at level α/n_candidates has the given power (3.40 for df=1)."""
    crit = stats.chi2.isf(alpha / n_candidates, df)
    f = lambda lam: stats.ncx2.sf(crit, df, lam**2) - power  # noqa: E731
    return float(optimize.brentq(f, 1e-3, 100.0))


def minimum_detectable(lam_of: Callable[[float], float], *, linear: bool = True, df: int = 1,
                       lo: float = 1e-3, hi: float = 1e6) -> float:
    """Magnitude m where λ(m) reaches :func:`threshold` (inf if never within [lo, hi]).

    ``linear``: λ is proportional to m (additive effects), so m* = thr/λ(1).
    Otherwise λ(m) is assumed increasing and bisected in log m (e.g. lag τ).
    """
    thr = threshold(df)
    if linear:
        lam1 = lam_of(1.0)
        return thr / lam1 if lam1 > 1e-12 else float("inf")
    if lam_of(hi) < thr:
        return float("inf")
    if lam_of(lo) >= thr:
        return lo
    a, b = np.log(lo), np.log(hi)
    for _ in range(60):
        m = 0.5 * (a + b)
        if lam_of(float(np.exp(m))) >= thr:
            b = m
        else:
            a = m
    return float(np.exp(b))


def row_noncentralities(x_g: np.ndarray, ref_g: np.ndarray, temp_c: np.ndarray,
                        sigma_g: np.ndarray) -> np.ndarray:
    """Per-reading λ_i of the leave-one-reading-out test: ‖r_i‖ with r = (I − P)x/σ,
    each axis scaled by 1/√(1 − h_ii) (h the leverage), (N,)."""
    X = base_design(ref_g, temp_c)
    sig = np.broadcast_to(np.asarray(sigma_g, float).reshape(len(X), -1), x_g.shape)
    lam2 = np.zeros(len(X))
    for i in range(3):
        w = 1.0 / sig[:, i]
        Xw, xw = X * w[:, None], x_g[:, i] * w
        Q, _ = np.linalg.qr(Xw)
        r = xw - Q @ (Q.T @ xw)
        h = np.sum(Q**2, axis=1)
        lam2 += r**2 / np.maximum(1.0 - h, 1e-12)
    return np.sqrt(lam2)


def threshold_rows(df_row: int, n_rows: int, alpha: float = ALPHA,
                   n_candidates: int = N_CANDIDATES) -> float:
    """Critical value of a df_row χ² per-reading test scanned over n_rows readings."""
    return float(stats.chi2.isf(alpha / (n_candidates * n_rows), df_row))


def minimum_detectable_rows(lam_rows_1: np.ndarray, df_row: int, n_rows: int,
                            power: float = POWER) -> float:
    """Magnitude m at which a scan over all n_rows readings finds at least one disturbed
    reading with probability ``power``; ``lam_rows_1``: λ_i at m = 1 of the disturbed
    readings (λ ∝ m). Each disturbed reading's statistic is non-central χ²(df_row, (mλ_i)²)
    and they are independent (one reading each)."""
    lam = np.asarray(lam_rows_1, float)
    lam = lam[lam > 1e-12]
    if lam.size == 0:
        return float("inf")
    crit = threshold_rows(df_row, n_rows)

    def f(m: float) -> float:
        miss = np.prod([stats.ncx2.cdf(crit, df_row, (m * li) ** 2) for li in lam])
        return (1.0 - miss) - power

    hi = 1.0 / float(lam.max())
    while f(hi) < 0:
        hi *= 2.0
    return float(optimize.brentq(f, 1e-9 * hi, hi, xtol=1e-10 * hi, rtol=1e-10))
