"""Joint thermal fit: one Levenberg–Marquardt (Eq. 7) over every reading of every step.

The unknowns are the polynomial coefficients of Eq. 8 themselves,
``p_k(T) = Σ_j c_kj x^j`` with ``x = (T − T_centre)/T_scale``, and each
reading is evaluated at its own (conditioned) temperature. The residuals are
those of the per-temperature fits (:mod:`calibration.fit`): per axis
``A(U − b) − ref`` over σ in reference mode, ``|A(U − b)| − g`` over the
projected σ in norm mode (Eq. 3). Started from the per-step polynomials, so
it only has to polish them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from calibration import sfem


@dataclass
class JointResult:
    coeffs: np.ndarray  # (12, d+1)
    coeff_stderr: np.ndarray  # (12, d+1), NaN where not fitted
    chi2_red: float
    nfev: int
    success: bool
    message: str


def fit_joint(
    raw_g: np.ndarray,
    ref_g: np.ndarray | None,
    sigma_g: np.ndarray,
    x: np.ndarray,
    coeffs0: np.ndarray,
    free: np.ndarray,
    *,
    g_local: float = 1.0,
) -> JointResult:
    """Fit the (free parameters × degree+1) coefficients to all readings at once."""
    raw = np.asarray(raw_g, float)
    sig = np.asarray(sigma_g, float)
    n_rows = raw.shape[0]
    n_coef = coeffs0.shape[1]
    V = np.vander(x, n_coef, increasing=True)  # (N, d+1)
    free_idx = np.flatnonzero(free)

    def full(q: np.ndarray) -> np.ndarray:
        c = coeffs0.copy()
        c[free_idx] = q.reshape(free_idx.size, n_coef)
        return c

    def params(q: np.ndarray) -> np.ndarray:
        return V @ full(q).T  # (N,12)

    if ref_g is not None:
        ref = np.asarray(ref_g, float)

        def residual(q: np.ndarray) -> np.ndarray:
            return ((sfem.forward(params(q), raw) - ref) / sig).ravel()

        def jacobian(q: np.ndarray) -> np.ndarray:
            _, jac = sfem.forward_jacobian(params(q), raw)
            jac = jac[:, :, free_idx] / sig[:, :, None]  # (N,3,F)
            return sfem.coefficient_jacobian(jac, V).reshape(3 * n_rows, -1)

    else:

        def residual(q: np.ndarray) -> np.ndarray:
            f = sfem.forward(params(q), raw)
            return (np.linalg.norm(f, axis=1) - g_local) / sfem.norm_sigma(f, sig)

        def jacobian(q: np.ndarray) -> np.ndarray:
            f, jac = sfem.forward_jacobian(params(q), raw)
            dn = sfem.norm_jacobian(f, jac[:, :, free_idx]) / sfem.norm_sigma(f, sig)[:, None]
            return sfem.coefficient_jacobian(dn, V)

    q0 = coeffs0[free_idx].ravel()
    sol = least_squares(residual, q0, jac=jacobian, method="lm", x_scale="jac")
    dof = max(sol.fun.size - q0.size, 1)
    chi2_red = float(np.sum(sol.fun**2) / dof)
    stderr = np.full(coeffs0.shape, np.nan)
    J = sol.jac
    try:
        cov = np.linalg.inv(J.T @ J) * chi2_red
        stderr[free_idx] = np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(free_idx.size, n_coef)
    except np.linalg.LinAlgError:
        pass
    return JointResult(full(sol.x), stderr, chi2_red, int(sol.nfev), bool(sol.success),
                       str(sol.message))
