"""Statistics after projecting out the current model, and their parametric-bootstrap null.

Given the whitened design X of the current model (base + accepted terms), every
statistic is a function of the residual ``e = (I − P_X) y``. Under the null
(base model + Gaussian noise, the parametric bootstrap of docs/diagnosis.md §2)
``e = (I − P_X) ε`` for any β, so a null replicate is one projection of
white noise: the projections are data-independent given the design, and B
replicates cost a few matrix products.

Statistics are normalised by a robust (MAD) noise scale of the same residual,
so they are scale-free: the null does not depend on the noise level, and an
underestimated sd/√n cannot cause false alarms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats as sps

ABSORBED_MAX = 0.99  # beyond this the base model swallows the effect: not identifiable here


def orthonormal_basis(X: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column space of X (SVD; rank-deficient columns dropped)."""
    if X.shape[1] == 0:
        return np.zeros((X.shape[0], 0))
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    keep = s > rel_tol * max(float(s[0]), 1e-300)
    return U[:, keep]


def project_out(U: np.ndarray, X: np.ndarray) -> np.ndarray:
    return X - U @ (U.T @ X)


def robust_scale(E: np.ndarray, dof_corr: float) -> np.ndarray:
    """MAD scale of residual columns (one per replicate), corrected for the fitted dof."""
    return 1.4826 * np.median(np.abs(E), axis=0) * dof_corr


def absorbed_fraction(U: np.ndarray, X: np.ndarray) -> float:
    """1 − ‖(I−P)X‖²/‖X‖²: how much of an effect the current model already explains."""
    tot = float(np.sum(X**2))
    if tot <= 0:
        return 1.0
    return 1.0 - float(np.sum(project_out(U, X) ** 2)) / tot


@dataclass
class CandidateTest:
    """One effect's test at this stage: statistic on the data and on each null replicate."""

    effect_id: str
    p_naive: float  # chi² tail of the (max over grid/rows) statistic
    multiplicity: int  # grid values or rows the max ran over
    p_adj: float  # Šidák-adjusted for that multiplicity
    p_adj_null: np.ndarray  # (B,) the same on the null replicates
    theta: float  # best grid value (nan when linear)
    absorbed: float
    stat: float
    profile: dict[float, float] = field(default_factory=dict)  # theta → stat (lag τ, boundary)


def sidak(p: np.ndarray | float, mult: int) -> np.ndarray:
    p = np.clip(np.asarray(p, float), 0.0, 1.0)
    return -np.expm1(mult * np.log1p(-np.minimum(p, 1 - 1e-16)))


def chi2_sf(stat: np.ndarray | float, k: int) -> np.ndarray:
    return sps.chi2.sf(np.maximum(np.asarray(stat, float), 0.0), k)


def linear_stats(U: np.ndarray, Xw: np.ndarray, e: np.ndarray, E: np.ndarray,
                 s: float, s_null: np.ndarray) -> tuple[float, np.ndarray, int, float]:
    """Score statistic of free-gain columns: ‖B'e‖²/s² with B an orthonormal basis of (I−P)X."""
    Z = project_out(U, Xw)
    absorbed = absorbed_fraction(U, Xw)
    B = orthonormal_basis(Z, 1e-6)
    k = B.shape[1]
    if k == 0:
        return 0.0, np.zeros(E.shape[1]), 0, 1.0
    # F-type: the noise scale is taken from the residual *after* the candidate, so the
    # effect itself does not inflate it (matters for short recordings, e.g. 33 rows).
    m, p = e.size, U.shape[1]
    dof = max(m - p - k, 1)
    q = float(np.sum((B.T @ e) ** 2))
    f = q / k / ((float(e @ e) - q) / dof)
    qn = np.sum((B.T @ E) ** 2, axis=0)
    fn = qn / k / ((np.sum(E**2, axis=0) - qn) / dof)
    # Reported on the χ²(k) scale (same p) so all candidates share one p-value function.
    return _f_as_chi2(f, k, dof), _f_as_chi2(fn, k, dof), k, absorbed


def _f_as_chi2(f: np.ndarray | float, k: int, dof: int) -> np.ndarray | float:
    logp = sps.f.logsf(np.maximum(f, 0.0), k, dof)
    return sps.chi2.isf(np.exp(np.maximum(logp, -700.0)), k)


def fixed_gain_stats(
    U: np.ndarray, xw: np.ndarray, Nw: np.ndarray, e: np.ndarray, E: np.ndarray, s: float,
    s_null: np.ndarray,
) -> tuple[float, np.ndarray, float]:
    """Drop in SS from adding free nuisance columns N and a term x with gain fixed at 1.

    ΔSS = ‖P_N' e‖² + 2 z'e' − z'z with N' = (I−P)N, z = (I−P_[X,N])x: bounded by
    the (1 + j)-dof score statistic, so its χ²(1 + j) tail is conservative.
    """
    Nb = orthonormal_basis(project_out(U, Nw), 1e-6) if Nw.shape[1] else np.zeros((e.size, 0))
    U2 = np.hstack([U, Nb])
    z = project_out(U2, xw[:, None])[:, 0]
    zz = float(z @ z)
    t = (float(np.sum((Nb.T @ e) ** 2)) + 2.0 * float(z @ e) - zz) / s**2
    tn = (np.sum((Nb.T @ E) ** 2, axis=0) + 2.0 * (z @ E) - zz) / s_null**2
    return t, tn, absorbed_fraction(U, xw[:, None])


def row_stats(U: np.ndarray, e: np.ndarray, E: np.ndarray, row: np.ndarray, n_rows: int,
              s: float, s_null: np.ndarray, skip: set[int]) -> tuple[np.ndarray, np.ndarray, int]:
    """Leave-one-reading-out statistic per reading: e_gᵀ(I − U_g U_gᵀ)⁻¹ e_g / s².

    Returns per-row stats on the data (N,), their max on each null replicate (B,),
    and the number of entries per reading (the dof).
    """
    g = int(np.bincount(row).max())
    idx = np.argsort(row, kind="stable").reshape(n_rows, g)
    Ug = U[idx]  # (N, g, p)
    M = np.eye(g)[None] - np.einsum("ngp,nhp->ngh", Ug, Ug)
    ok = np.array([i not in skip for i in range(n_rows)]) & (np.linalg.det(M) > 1e-6)
    Minv = np.zeros_like(M)
    Minv[ok] = np.linalg.inv(M[ok])
    eg = e[idx]
    t = np.einsum("ng,ngh,nh->n", eg, Minv, eg) / s**2
    Eg = E[idx]  # (N, g, B)
    tn = np.einsum("ngb,ngh,nhb->nb", Eg, Minv, Eg) / s_null[None, :] ** 2
    return t, tn.max(axis=0), g
