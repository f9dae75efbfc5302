"""Many small reference-mode SFEM fits at once: ``bench_speed.py``'s batch path.

Only the speed benchmark uses this (the calibration fits one problem at a time through
:func:`calibration.fitting.fit`); each row equals :func:`calibration.fit.fit_reference`,
which the benchmark checks on 200 problems.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration import sfem
from calibration.errors import NotIdentifiable
from calibration.fit import fit_reference


@dataclass
class BatchFitResult:
    """K reference-mode fits (:func:`fit_reference_batch`); row k equals ``fit_reference`` k."""

    params: np.ndarray  # (K,12) SFEM vectors
    covariance: np.ndarray  # (K,12,12), scaled by reduced chi²; NaN where rank-deficient
    rmse_norm_ug: np.ndarray  # (K,) Eq. 9 after calibration
    rmse_norm_before_ug: np.ndarray  # (K,)
    rmse_vector_ug: np.ndarray  # (K,)
    chi2_red: np.ndarray  # (K,)
    identifiable: np.ndarray  # (K,) bool: all 12 parameters determined

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diagonal(self.covariance, axis1=1, axis2=2), 0.0, None))

    def sfem(self, k: int) -> sfem.SfemParams:
        return sfem.SfemParams.from_vector(self.params[k])


def fit_reference_batch(
    raw_g: np.ndarray,
    ref_g: np.ndarray,
    sigma_g: np.ndarray | None = None,
    *,
    g_local: float = 1.0,
    gn_iterations: int = 1,
) -> BatchFitResult:
    """K independent reference-mode fits, vectorised: raw, ref (K,N,3), sigma (K,N,3) or None.

    The reference residual A(U − b) − ref is linear in (A, c = −A b), so the weighted
    linear least squares ``ref = A·U + c`` (per output axis, batched QR) *is* the
    optimum that :func:`fit_reference`'s LM converges to; (A, b) → (M, C, S, b) is a
    bijection for det A > 0. ``gn_iterations`` Gauss-Newton steps in the SFEM
    parameters then only polish rounding and give the Jacobian for the covariance.
    Problems whose A is not a proper rotation-times-triangular (det ≤ 0) fall back to
    the single fit, so every row matches :func:`fit_reference`.
    """
    raw = np.asarray(raw_g, dtype=float)
    ref = np.asarray(ref_g, dtype=float)
    if raw.ndim != 3 or raw.shape[2] != 3:
        raise ValueError(f"raw_g must have shape (K, N, 3), got {raw.shape}")
    if ref.shape != raw.shape:
        raise ValueError(f"raw_g {raw.shape} and ref_g {ref.shape} differ in shape")
    if not (np.all(np.isfinite(raw)) and np.all(np.isfinite(ref))):
        raise ValueError("raw_g/ref_g contain non-finite values")
    K, n, _ = raw.shape
    if n < 4:
        raise NotIdentifiable(f"reference fit needs at least 4 positions, got {n}")
    sig = _sigma_batch(sigma_g, raw.shape)

    # Closed form, per output axis: rows of [U, 1] weighted by 1/σ_k.
    X = np.concatenate([raw, np.ones((K, n, 1))], axis=2)  # (K,N,4)
    w = np.moveaxis(1.0 / sig, 2, 1)  # (K,3,N)
    Xw = X[:, None, :, :] * w[..., None]  # (K,3,N,4)
    yw = np.moveaxis(ref, 2, 1) * w  # (K,3,N)
    Q, R = np.linalg.qr(Xw)
    coef = np.linalg.solve(R, np.swapaxes(Q, 2, 3) @ yw[..., None])[..., 0]  # (K,3,4)
    A, c = coef[..., :3], coef[..., 3]
    P = np.empty((K, sfem.N_PARAMS))
    det = np.linalg.det(A)
    ok = det > 0
    P[~ok] = sfem.identity_vector()
    if ok.any():
        P[ok] = sfem.vector_from_matrix(A[ok], -np.linalg.solve(A[ok], c[ok][..., None])[..., 0])

    def weighted(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # f = A(U − b) is linear in v = U − b, so ∂f/∂p is too: evaluate the analytic
        # Jacobian once per problem at v = e_x, e_y, e_z (3K rows, not NK) and combine.
        # ∂f/∂b = −A does not depend on v at all.
        basis = p[:, None, sfem.BIAS] + np.eye(3)[None]  # (K,3,3): raw giving v = e_j
        _, g = sfem.forward_jacobian(np.repeat(p, 3, axis=0), basis.reshape(-1, 3))
        g = g.reshape(K, 3, 3, sfem.N_PARAMS)  # [k, j, axis, param]
        v = raw - p[:, None, sfem.BIAS]
        f = sfem.forward(p, raw)
        jac = np.empty((K, n, 3, sfem.N_PARAMS))
        jac[..., sfem.BIAS] = g[:, :1, :, sfem.BIAS]
        jac[..., 3:] = (v @ g[..., 3:].reshape(K, 3, 27)).reshape(K, n, 3, 9)
        r = (f - ref) / sig
        J = jac / sig[..., None]
        return r.reshape(K, 3 * n), J.reshape(K, 3 * n, sfem.N_PARAMS)

    r, J = weighted(P)
    for _ in range(max(int(gn_iterations), 0)):
        Jt = np.swapaxes(J, 1, 2)
        try:
            delta = np.linalg.solve(Jt @ J, -(Jt @ r[..., None]))[..., 0]
        except np.linalg.LinAlgError:
            break
        trial = P + np.where(ok[:, None], delta, 0.0)
        r2, J2 = weighted(trial)
        better = np.sum(r2**2, axis=1) <= np.sum(r**2, axis=1)
        P = np.where(better[:, None], trial, P)
        r = np.where(better[:, None], r2, r)
        J = np.where(better[:, None, None], J2, J)

    dof = max(3 * n - sfem.N_PARAMS, 1)
    chi2 = np.sum(r**2, axis=1) / dof
    cov = np.full((K, sfem.N_PARAMS, sfem.N_PARAMS), np.nan)
    # Singular values of J via its 12×12 triangular factor: same values, far less work.
    sv = np.linalg.svd(np.linalg.qr(J, mode="r"), compute_uv=False)
    full_rank = sv[:, -1] > 1e-10 * sv[:, 0]
    if full_rank.any():
        Jf = J[full_rank]
        JtJ = np.swapaxes(Jf, 1, 2) @ Jf
        cov[full_rank] = np.linalg.inv(JtJ) * np.maximum(chi2[full_rank], 1e-300)[:, None, None]

    out = BatchFitResult(
        params=P, covariance=cov, rmse_norm_ug=np.empty(K), rmse_norm_before_ug=np.empty(K),
        rmse_vector_ug=np.empty(K), chi2_red=chi2, identifiable=full_rank,
    )
    cal = sfem.forward(P, raw)
    out.rmse_norm_ug[:] = np.sqrt(np.mean((np.linalg.norm(cal, axis=2) - g_local) ** 2, 1)) * 1e6
    out.rmse_norm_before_ug[:] = (
        np.sqrt(np.mean((np.linalg.norm(raw, axis=2) - g_local) ** 2, axis=1)) * 1e6)
    out.rmse_vector_ug[:] = np.sqrt(np.mean((cal - ref) ** 2, axis=(1, 2))) * 1e6
    for k in np.flatnonzero(~ok):  # rare: let the single LM fit handle it
        single = fit_reference(raw[k], ref[k], None if sigma_g is None else sig[k],
                               g_local=g_local)
        out.params[k] = single.params.to_vector()
        out.covariance[k] = single.covariance
        out.rmse_norm_ug[k] = single.rmse_norm_ug
        out.rmse_vector_ug[k] = single.rmse_vector_ug or np.nan
        out.chi2_red[k] = single.chi2_red
        out.identifiable[k] = bool(single.identifiable.all())
    return out


def _sigma_batch(sigma_g: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """:func:`_sigma` for (K,N,3) at once; problems with unusable σ go through _sigma."""
    if sigma_g is None:
        return np.ones(shape)
    sig = np.broadcast_to(np.asarray(sigma_g, dtype=float), shape).copy()
    bad = ~np.isfinite(sig) | (sig <= 0)
    for k in np.flatnonzero(bad.any(axis=(1, 2))):  # rows without a usable σ: the median
        ok = ~bad[k]
        sig[k] = np.where(bad[k], np.median(sig[k][ok]) if ok.any() else 1.0,
                          sig[k] if ok.any() else 1.0)
    return sig
