"""The base model, linearised over the whole recording (docs/diagnosis.md §1).

Reference mode is *exactly* linear: the SFEM (seed Eq. 1) solved for the raw
output is ``raw = A(T)⁻¹ ref + b(T)``; with each SFEM parameter a cubic in T
(seed Eq. 8) the entries of ``G = A⁻¹`` are cubics to far below the noise
(the remainder is products of tempcos, < 0.01 µg), so per axis::

    raw_a = Σ_j Σ_p β[a,j,p] · u_j · t^p,   u = (1, ref_x, ref_y, ref_z), p = 0..3

48 coefficients (12 parameters × 4 powers) and a block-diagonal design.
Norm mode linearises ``|A(T)(raw − b(T))| − 1`` around a Gauss–Newton fit of
the 9 identifiable parameters (M is invisible to |g|) × powers of T.

Everything is whitened by σ = sd/√n (or a residual estimate when sd is
absent), so that statistics are in units of the noise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration import fit as sfem_fit
from calibration import sfem_batch
from calibration.discrepancy.context import DesignContext, base_context
from calibration.recording import Recording

Lift = Callable[[np.ndarray], np.ndarray]


@dataclass
class LinearProblem:
    """``y = X0·β + (effect columns)·θ + noise`` in residual space (m entries)."""

    mode: str
    y: np.ndarray  # (m,) data vector (raw output, or norm residual of the base fit), g
    X0: np.ndarray  # (m, p0) base design, unweighted
    w: np.ndarray  # (m,) whitening weights 1/σ
    row: np.ndarray  # (m,) reading index of each entry
    axis: np.ndarray  # (m,) axis of each entry (−1 in norm mode)
    lift: Lift  # raw-space (N,3,k) → residual space (m,k)
    ctx: DesignContext
    noise_from_sd: bool
    degree: int
    t_mid_c: float
    t_half_c: float

    @property
    def m(self) -> int:
        return self.y.size

    def whiten(self, a: np.ndarray) -> np.ndarray:
        return a * (self.w if a.ndim == 1 else self.w[:, None])


def pooled_sigma_g(rec: Recording, steps: np.ndarray) -> np.ndarray | None:
    """σ of each reading: the per-(step, axis) median of ``sd_*`` over √n.

    Why: each row's own sd is itself a noisy estimate (χ with n−1 dof); whitening
    by it gives heavier-than-Gaussian tails and false outliers. Pooling per step
    keeps real changes of the noise (vibration, temperature) and drops the χ noise.
    """
    if rec.sigma_g is None:
        return None
    sd = np.column_stack([rec.columns[c] for c in ("sd_x", "sd_y", "sd_z")])
    n = rec.columns.get("n")
    n = np.ones(len(rec)) if n is None else np.where(np.isfinite(n) & (n > 0), n, 1.0)
    pooled = np.empty_like(sd)
    for s_ in np.unique(steps):
        m = steps == s_
        pooled[m] = np.nanmedian(sd[m], axis=0)
    return pooled / np.sqrt(n)[:, None]


def build_problem(rec: Recording) -> LinearProblem:
    if rec.has_reference:
        return _reference_problem(rec)
    return _norm_problem(rec)


def _powers(temp: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, int, float, float]:
    n_temps = len({round(float(np.median(temp[steps == s])), 1) for s in np.unique(steps)})
    degree = int(max(0, min(3, n_temps - 1)))
    lo, hi = float(np.min(temp)), float(np.max(temp))
    mid, half = (lo + hi) / 2.0, max((hi - lo) / 2.0, 1e-6)
    t = (temp - mid) / half
    return np.column_stack([t**p for p in range(degree + 1)]), degree, mid, half


def _reference_problem(rec: Recording) -> LinearProblem:
    raw, ref = rec.raw_g, rec.ref_g
    assert ref is not None
    n = raw.shape[0]
    ctx = base_context(rec, "reference", ref)
    P, degree, mid, half = _powers(ctx.temp_c, ctx.steps)
    u = np.column_stack([np.ones(n), ref])  # (N,4)
    block = (u[:, :, None] * P[:, None, :]).reshape(n, -1)  # (N, 4·(d+1))
    k = block.shape[1]
    X0 = np.zeros((n, 3, 3 * k))
    for a in range(3):
        X0[:, a, a * k:(a + 1) * k] = block
    X0 = X0.reshape(3 * n, 3 * k)
    y = raw.ravel()
    sig = pooled_sigma_g(rec, ctx.steps)
    from_sd = sig is not None and bool(np.all(np.isfinite(sig) & (sig > 0)))
    if not from_sd:
        beta = np.linalg.lstsq(X0, y, rcond=None)[0]
        e = (y - X0 @ beta).reshape(n, 3)
        dof_corr = np.sqrt(3 * n / max(3 * n - X0.shape[1], 1))
        s = 1.4826 * np.median(np.abs(e - np.median(e, axis=0)), axis=0) * dof_corr
        sig = np.broadcast_to(np.maximum(s, 1e-9), (n, 3))
    w = 1.0 / np.asarray(sig, float).ravel()
    beta = np.linalg.lstsq(X0 * w[:, None], y * w, rcond=None)[0]
    # ∂raw/∂T of the fitted base, for the lag regressor (its gain is locked to this).
    dP = np.column_stack([np.zeros(n)] + [p * P[:, p - 1] for p in range(1, degree + 1)]) / half
    dblock = (u[:, :, None] * dP[:, None, :]).reshape(n, -1)
    ctx.draw_dtemp_g_per_c = np.column_stack([dblock @ beta[a * k:(a + 1) * k] for a in range(3)])

    def lift(x: np.ndarray) -> np.ndarray:
        return x.reshape(3 * n, -1)

    return LinearProblem(
        "reference", y, X0, w, np.repeat(np.arange(n), 3), np.tile(np.arange(3), n), lift, ctx,
        from_sd, degree, mid, half,
    )


def _norm_problem(rec: Recording) -> LinearProblem:
    raw = rec.raw_g
    n = raw.shape[0]
    start = sfem_fit.fit_norm(raw, rec.sigma_g)
    free = sfem_fit.NORM_FREE
    ctx0 = base_context(rec, "norm", raw)
    P, degree, mid, half = _powers(ctx0.temp_c, ctx0.steps)
    npow = P.shape[1]
    q = np.zeros((free.sum(), npow))
    q[:, 0] = start.params.to_vector()[free]
    fixed = start.params.to_vector()

    def params(qq: np.ndarray) -> np.ndarray:
        Pm = np.tile(fixed, (n, 1))
        Pm[:, free] = P @ qq.T
        return Pm

    for _ in range(8):  # Gauss–Newton on the 9×(d+1) coefficients; starts at the pooled fit
        Pm = params(q)
        f, jac = sfem_batch.forward_jacobian(Pm, raw)
        nf = np.linalg.norm(f, axis=1)
        r = nf - 1.0
        ju = np.einsum("ni,nij->nj", f / nf[:, None], jac[:, :, free])  # (N,9)
        J = (ju[:, :, None] * P[:, None, :]).reshape(n, -1)
        step = np.linalg.lstsq(J, -r, rcond=None)[0].reshape(q.shape)
        q = q + step
        if np.max(np.abs(step)) < 1e-12:
            break
    Pm = params(q)
    f, jac = sfem_batch.forward_jacobian(Pm, raw)
    nf = np.linalg.norm(f, axis=1)
    uvec = f / nf[:, None]
    A = sfem_batch.matrices(Pm)
    gvec = np.einsum("ni,nij->nj", uvec, A)  # ∂|f|/∂raw
    ju = np.einsum("ni,nij->nj", uvec, jac[:, :, free])
    X0 = (ju[:, :, None] * P[:, None, :]).reshape(n, -1)
    y = nf - 1.0
    ctx = base_context(rec, "norm", f)
    sig = pooled_sigma_g(rec, ctx.steps)
    from_sd = sig is not None and bool(np.all(np.isfinite(sig) & (sig > 0)))
    if from_sd:
        s_norm = np.sqrt(np.sum((gvec * sig) ** 2, axis=1))
    else:
        beta = np.linalg.lstsq(X0, y, rcond=None)[0]
        e = y - X0 @ beta
        corr = np.sqrt(n / max(n - X0.shape[1], 1))
        s_norm = np.full(n, max(1.4826 * np.median(np.abs(e - np.median(e))) * corr, 1e-9))
    if degree > 0:
        h = 0.01 * half
        Pm_h = np.tile(fixed, (n, 1))
        th = (ctx0.temp_c + h - mid) / half
        Pm_h[:, free] = np.column_stack([th**p for p in range(npow)]) @ q.T
        raw_h = np.linalg.solve(sfem_batch.matrices(Pm_h), f[:, :, None])[:, :, 0] + Pm_h[:, 0:3]
        raw_0 = np.linalg.solve(A, f[:, :, None])[:, :, 0] + Pm[:, 0:3]
        ctx.draw_dtemp_g_per_c = (raw_h - raw_0) / h

    def lift(x: np.ndarray) -> np.ndarray:
        return np.einsum("na,nak->nk", gvec, x.reshape(n, 3, -1))

    return LinearProblem(
        "norm", y, X0, 1.0 / s_norm, np.arange(n), np.full(n, -1), lift, ctx, from_sd,
        degree, mid, half,
    )
