"""Levenberg–Marquardt fits of the SFEM (Eq. 1) at one temperature (Eq. 4–7).

Two modes:

* **reference mode** -- each reading has a reference specific force ``ref_g``
  (turntable orientation known): residual ``A(U − b) − ref`` per axis. All 12
  parameters are identifiable with a rich enough schedule. Start: closed-form
  linear least squares ``ref = A·U + c``, decomposed by :func:`sfem.from_matrix`.
* **norm mode** -- only |g| is known (hand-placed or unknown orientation):
  residual ``|A(U − b)| − g`` (Eq. 3). The misalignment rotation M cannot be
  seen by a norm, so only b, S and C (9 parameters) are fitted; M is reported
  as not identifiable. Start: linear ellipsoid fit.

``scipy.optimize.least_squares(method="lm")`` with the analytic Jacobian of
:func:`sfem.forward_jacobian` implements Eq. 7 (Levenberg–Marquardt with the
diagonal scaling), weights W = 1/σ² from ``sd_*``/√n when available.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import OptimizeResult, brentq, least_squares
from scipy.stats import chi2 as _chi2

from calibration import sfem
from calibration.errors import NotIdentifiable
from calibration.gate import (
    NORM_MIN_ORIENTATIONS,
    REFERENCE_MIN_ORIENTATIONS,
    STRUCTURAL_REL_TOL,
    capacity,
    undetermined_parameters,
)

NORM_FREE = np.array([True] * 9 + [False] * 3)  # M is invisible to |g|


@dataclass
class FitResult:
    """Everything one SFEM fit produced (like scipy's OptimizeResult, but named)."""

    mode: str  # "reference" | "norm"
    params: sfem.SfemParams
    covariance: np.ndarray  # (12,12), scaled by reduced chi²; NaN rows/cols where not identifiable
    identifiable: np.ndarray  # (12,) bool
    residuals_g: np.ndarray  # reference: (N,3) calibrated − ref; norm: (N,) |cal| − g
    rmse_norm_ug: float  # Eq. 9 after calibration, µg
    rmse_norm_before_ug: float  # Eq. 9 on the raw readings, µg
    rmse_vector_ug: float | None  # reference mode: RMS of per-axis error, µg
    chi2_red: float
    n_positions: int
    nfev: int
    success: bool
    message: str
    g_local: float = 1.0
    not_identifiable_why: dict[str, str] = field(default_factory=dict)
    # σ_model (g) added in quadrature to every reading's sd/√n (see :func:`model_floor_g`);
    # 0.0 when the residuals are consistent with the recorded noise, NaN with equal weights.
    model_floor_g: float = float("nan")
    # Hand-placed references: the orientation uncertainty (rad) per position, else None.
    ref_tol_rad: np.ndarray | None = None

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def fit_reference(
    raw_g: np.ndarray,
    ref_g: np.ndarray,
    sigma_g: np.ndarray | None = None,
    *,
    g_local: float = 1.0,
    model_floor: float | str | None = "auto",
    ref_tol_rad: np.ndarray | float | None = None,
) -> FitResult:
    """Fit all 12 SFEM parameters from readings with known references (Eq. 4–7).

    ``model_floor`` (with ``sigma_g``): "auto" adds σ_model, chosen from the fit's own
    residual excess (:func:`model_floor_g`), in quadrature to sd/√n; a number (g) fixes
    it; None or 0 uses sd/√n alone. ``ref_tol_rad`` (scalar or per position, > 0):
    the references are hand-placed, known only to that angle -- see
    :func:`_fit_hand_placed`.
    """
    raw, ref = _as_n3(raw_g, "raw_g"), _as_n3(ref_g, "ref_g")
    if raw.shape != ref.shape:
        raise ValueError(f"raw_g {raw.shape} and ref_g {ref.shape} differ in shape")
    n = raw.shape[0]
    _check_capacity(raw, "reference")
    sig = _sigma(sigma_g, n)
    tol = None
    if ref_tol_rad is not None:
        tol = np.broadcast_to(np.asarray(ref_tol_rad, dtype=float), (n,)).copy()
        if not np.all(np.isfinite(tol) & (tol > 0)):
            raise ValueError("ref_tol_rad must be positive and finite for every position")

    def once(s: np.ndarray) -> FitResult:
        if tol is not None:
            return _fit_hand_placed(raw, ref, s, tol, g_local)
        return _fit_reference_once(raw, ref, s, g_local)

    return _with_floor(once, raw, sig, sigma_g is not None, model_floor)


def _fit_reference_once(
    raw: np.ndarray, ref: np.ndarray, sig: np.ndarray, g_local: float
) -> FitResult:
    n = raw.shape[0]
    p0 = linear_reference_start(raw, ref, sig)

    def residual(p: np.ndarray) -> np.ndarray:
        return ((sfem.forward(p, raw) - ref) / sig).ravel()

    def jacobian(p: np.ndarray) -> np.ndarray:
        _, jac = sfem.forward_jacobian(p, raw)
        return (jac / sig[:, :, None]).reshape(3 * n, sfem.N_PARAMS)

    sol = least_squares(residual, p0, jac=jacobian, method="lm", x_scale="jac")
    dof = max(3 * n - sfem.N_PARAMS, 1)
    chi2_red = float(np.sum(sol.fun**2) / dof)
    cov, ident = _covariance(sol.jac, chi2_red, np.ones(sfem.N_PARAMS, bool))
    unseen = _structurally_undetermined(ref, "reference")
    if unseen:
        mask = np.isin(np.array(sfem.PARAM_NAMES), unseen)
        ident &= ~mask
        cov[mask, :] = np.nan
        cov[:, mask] = np.nan
    return _reference_result(sol, raw, ref, cov, ident, chi2_red, g_local)


def _reference_result(
    sol: OptimizeResult,
    raw: np.ndarray,
    ref: np.ndarray,
    cov: np.ndarray,
    ident: np.ndarray,
    chi2_red: float,
    g_local: float,
    ref_tol_rad: np.ndarray | None = None,
) -> FitResult:
    """The one :class:`FitResult` of a reference-mode fit (exact or hand-placed labels).

    Residuals are the Eq. 4 vector residuals ``A(U − b) − ref``; the |g| figures are
    Eq. 9 before and after. ``ref_tol_rad`` is kept for a hand-placed fit so a refit
    with a model floor treats the labels as approximate again.
    """
    params = sfem.SfemParams.from_vector(sol.x)
    cal = params.apply(raw)
    res = cal - ref
    return FitResult(
        mode="reference",
        params=params,
        covariance=cov,
        identifiable=ident,
        residuals_g=res,
        rmse_norm_ug=rmse_norm_ug(cal, g_local),
        rmse_norm_before_ug=rmse_norm_ug(raw, g_local),
        rmse_vector_ug=float(np.sqrt(np.mean(res**2)) * 1e6),
        chi2_red=chi2_red,
        n_positions=raw.shape[0],
        nfev=int(sol.nfev),
        success=bool(sol.success),
        message=str(sol.message),
        g_local=g_local,
        not_identifiable_why=_why(ident),
        ref_tol_rad=None if ref_tol_rad is None else ref_tol_rad.copy(),
    )


def fit_norm(
    raw_g: np.ndarray,
    sigma_g: np.ndarray | None = None,
    *,
    g_local: float = 1.0,
    model_floor: float | str | None = "auto",
) -> FitResult:
    """Fit b, S, C from |g| alone (Eq. 3 as the residual); M is not identifiable.

    ``model_floor`` as in :func:`fit_reference`.
    """
    raw = _as_n3(raw_g, "raw_g")
    n = raw.shape[0]
    _check_capacity(raw, "norm")
    sig = _sigma(sigma_g, n)
    return _with_floor(lambda s: _fit_norm_once(raw, s, g_local), raw, sig,
                       sigma_g is not None, model_floor)


def _fit_norm_once(raw: np.ndarray, sig: np.ndarray, g_local: float) -> FitResult:
    n = raw.shape[0]
    undetermined = _structurally_undetermined(raw, "norm")
    # Parameters the directions cannot see stay at their nominal value: letting
    # LM wander along a (near-)null direction would corrupt the others.
    free = NORM_FREE & ~np.isin(np.array(sfem.PARAM_NAMES), undetermined)
    p0 = ellipsoid_start(raw, g_local)
    p0[~free] = sfem.identity_vector()[~free]

    def full(q: np.ndarray) -> np.ndarray:
        p = sfem.identity_vector()
        p[free] = q
        return p

    def residual(q: np.ndarray) -> np.ndarray:
        f = sfem.forward(full(q), raw)
        return (np.linalg.norm(f, axis=1) - g_local) / sfem.norm_sigma(f, sig)

    def jacobian(q: np.ndarray) -> np.ndarray:
        f, jac = sfem.forward_jacobian(full(q), raw)
        return sfem.norm_jacobian(f, jac[:, :, free]) / sfem.norm_sigma(f, sig)[:, None]

    sol = least_squares(residual, p0[free], jac=jacobian, method="lm", x_scale="jac")
    pv = full(sol.x)
    params = sfem.SfemParams.from_vector(pv)
    cal = params.apply(raw)
    res = np.linalg.norm(cal, axis=1) - g_local
    dof = max(n - int(free.sum()), 1)
    chi2_red = float(np.sum(sol.fun**2) / dof)
    cov, ident = _covariance(sol.jac, chi2_red, free)
    why = _why(ident, norm_mode=True)
    why.update({name: _UNSEEN for name in undetermined if name not in ("mx", "my", "mz")})
    return FitResult(
        mode="norm",
        params=params,
        covariance=cov,
        identifiable=ident,
        residuals_g=res,
        rmse_norm_ug=rmse_norm_ug(cal, g_local),
        rmse_norm_before_ug=rmse_norm_ug(raw, g_local),
        rmse_vector_ug=None,
        chi2_red=chi2_red,
        n_positions=n,
        nfev=int(sol.nfev),
        success=bool(sol.success),
        message=str(sol.message),
        g_local=g_local,
        not_identifiable_why=why,
    )


def rmse_norm_ug(cal_g: np.ndarray, g_local: float = 1.0) -> float:
    """Eq. 9: RMS of (|a| − g) over positions, in µg."""
    return float(np.sqrt(np.mean((np.linalg.norm(cal_g, axis=1) - g_local) ** 2)) * 1e6)


# --- weights with a model-error floor ----------------------------------------
# A floor is only added when the residuals exceed the recorded noise beyond what
# chance gives this often (χ² upper tail): on data the model describes within noise
# (every simulation of the seed's model) the weights stay sd/√n exactly.
FLOOR_SIGNIFICANCE = 0.01
FLOOR_ITERATIONS = 6


def model_floor_g(residual_g: np.ndarray, sigma_g: np.ndarray, n_params: int) -> float:
    """σ_model (g) with Σ r_i² / (σ_i² + σ_model²) = N − p (the Paule–Mandel equation).

    The weighted residual sum χ² = Σ r²/σ² of a fit whose model is right is χ²(N − p)
    distributed. When it exceeds the (1 − :data:`FLOOR_SIGNIFICANCE`) quantile, the
    excess is model error -- structure the linear SFEM (Eq. 1) leaves, placement
    transients -- that does not shrink with averaging, so it enters every reading's
    variance equally: σ_i² = sd_i²/n_i + σ_model². Without it, a 40 s rest with a
    sd/√n five times smaller than a 3 s interval's gets 25× its weight although its
    model error is the same (docs/realdata.md). Returns 0.0 when χ² is within noise
    or there are no spare degrees of freedom.
    """
    r = np.asarray(residual_g, float).ravel()
    s = np.asarray(sigma_g, float).ravel()
    dof = r.size - int(n_params)
    if dof < 1:
        return 0.0
    chi2 = float(np.sum((r / s) ** 2))
    if chi2 <= float(_chi2.ppf(1.0 - FLOOR_SIGNIFICANCE, dof)):
        return 0.0
    upper = float(np.sum(r**2)) / dof  # there Σ r²/(σ² + t) < Σ r²/t = dof

    def excess(t2: float) -> float:
        return float(np.sum(r**2 / (s**2 + t2))) - dof

    if excess(upper) > 0:  # only when σ is negligible against the residuals
        return float(np.sqrt(upper))
    return float(np.sqrt(brentq(excess, 0.0, upper, xtol=1e-30, rtol=1e-10)))


def _floor_residuals(res: FitResult, raw: np.ndarray, sig: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, int]:
    """(residual, its σ from sd/√n, parameters behind it) as the floor sees the fit."""
    if res.mode == "reference" and res.ref_tol_rad is None:
        return res.residuals_g, sig, sfem.N_PARAMS
    # Norm residuals (norm mode; the |g| part of a hand-placed fit): b, S, C set them.
    cal = res.params.apply(raw)
    return np.linalg.norm(cal, axis=1) - res.g_local, sfem.norm_sigma(cal, sig), 9


def _with_floor(
    once: Callable[[np.ndarray], FitResult],
    raw: np.ndarray,
    sig: np.ndarray,
    weighted: bool,
    model_floor: float | str | None,
) -> FitResult:
    """Run ``once(σ)`` with σ² = sd²/n + σ_model² (σ_model per ``model_floor``)."""
    if not weighted or model_floor is None or (
            not isinstance(model_floor, str) and float(model_floor) == 0.0):
        res = once(sig)
        res.model_floor_g = 0.0 if weighted else float("nan")
        return res
    if not isinstance(model_floor, str):
        tau = float(model_floor)
        if not (np.isfinite(tau) and tau > 0):
            raise ValueError(f"model_floor must be 'auto', None or a positive number (g), "
                             f"got {model_floor!r}")
        res = once(np.sqrt(sig**2 + tau**2))
        res.model_floor_g = tau
        return res
    if model_floor != "auto":
        raise ValueError(f"model_floor must be 'auto', None or a number, got {model_floor!r}")
    res, tau = once(sig), 0.0
    for _ in range(FLOOR_ITERATIONS):  # residuals move with the weights: a fixed point
        new_tau = model_floor_g(*_floor_residuals(res, raw, sig))
        if new_tau == 0.0 and tau == 0.0:
            break
        converged = abs(new_tau - tau) <= 1e-3 * max(new_tau, tau)
        tau = new_tau
        res = once(np.sqrt(sig**2 + tau**2))
        if converged:
            break
    res.model_floor_g = tau
    return res


# --- hand-placed references ---------------------------------------------------
def _fit_hand_placed(
    raw: np.ndarray, ref: np.ndarray, sig: np.ndarray, tol_rad: np.ndarray, g_local: float
) -> FitResult:
    """Reference-mode fit whose reference directions are known only to ``tol_rad``.

    A sensor put on a cube face by hand sits a degree or so off the labelled axis.
    Fitting ``A(U − b) = ref`` (Eq. 4) as if exact turns that tilt into
    misalignment and non-orthogonality and, through them, into |g| errors at every
    other orientation. Here each position contributes two kinds of residual:

    * its |g| error, ``(|A(U − b)| − g)/σ_i`` (Eq. 3): gravity's magnitude does not
      depend on how the sensor was placed, so it keeps its full weight;
    * its direction error, ``(f/|f| − r̂)/θ_i`` with θ_i the placement uncertainty:
      a Gaussian prior on a small per-position rotation, linearised.

    With θ ≫ σ/g (1° against 10⁻⁴ g) the |g| residuals decide b, S and the
    |g|-visible part of C exactly as a norm-mode fit would, and the labels only
    decide what |g| cannot see (the rotation M, and C where the positions are too few
    for norm mode -- six faces): the equivalent, in one LM, of "norm mode with the
    reference used for the axis assignment". Uses the analytic Jacobian of
    :func:`sfem.forward_jacobian`.
    """
    n = raw.shape[0]
    r_hat = ref / np.linalg.norm(ref, axis=1, keepdims=True)
    p0 = linear_reference_start(raw, ref, sig)

    def parts(p: np.ndarray) -> tuple[np.ndarray, ...]:
        f, jac = sfem.forward_jacobian(p, raw)
        norm = np.linalg.norm(f, axis=1)
        return f, jac, norm, f / norm[:, None], sfem.norm_sigma(f, sig)

    def residual(p: np.ndarray) -> np.ndarray:
        _, _, norm, u, s_norm = parts(p)
        return np.concatenate([(norm - g_local) / s_norm,
                               ((u - r_hat) / tol_rad[:, None]).ravel()])

    def jacobian(p: np.ndarray) -> np.ndarray:
        f, jac, norm, u, s_norm = parts(p)
        dnorm = sfem.norm_jacobian(f, jac)
        # ∂û/∂p = (I − û ûᵀ) ∂f/∂p / |f|: the direction's derivative for the label prior.
        proj = np.eye(3)[None] - u[:, :, None] * u[:, None, :]
        du = np.einsum("nij,njk->nik", proj, jac) / norm[:, None, None]
        return np.vstack([dnorm / s_norm[:, None],
                          (du / tol_rad[:, None, None]).reshape(3 * n, sfem.N_PARAMS)])

    sol = least_squares(residual, p0, jac=jacobian, method="lm", x_scale="jac")
    # n |g| residuals + 2n direction components (the third is second order) − 12.
    dof = max(3 * n - sfem.N_PARAMS, 1)
    chi2_red = float(np.sum(sol.fun**2) / dof)
    cov, ident = _covariance(sol.jac, chi2_red, np.ones(sfem.N_PARAMS, bool))
    return _reference_result(sol, raw, ref, cov, ident, chi2_red, g_local, tol_rad)


def linear_reference_start(raw: np.ndarray, ref: np.ndarray, sig: np.ndarray) -> np.ndarray:
    """Closed form: ref = A·U + c by weighted linear least squares, then b = −A⁻¹c."""
    X = np.hstack([raw, np.ones((raw.shape[0], 1))])
    coef = np.empty((4, 3))
    for k in range(3):
        w = 1.0 / sig[:, k]
        coef[:, k], *_ = np.linalg.lstsq(X * w[:, None], ref[:, k] * w, rcond=None)
    A = coef[:3].T
    c = coef[3]
    try:
        b = -np.linalg.solve(A, c)
        return sfem.from_matrix(A, b).to_vector()
    except (np.linalg.LinAlgError, ValueError):
        return sfem.identity_vector()


def ellipsoid_start(raw: np.ndarray, g_local: float = 1.0) -> np.ndarray:
    """Linear fit of the quadric (U − b)ᵀ Q (U − b) = g², Q = Aᵀ A with A lower triangular."""
    x, y, z = raw.T
    D = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z])
    try:
        v, *_ = np.linalg.lstsq(D, np.ones(len(raw)), rcond=None)
        Q = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
        b = -np.linalg.solve(Q, v[6:9])
        k = 1.0 + b @ Q @ b
        Q = Q / k * g_local**2
        if np.any(np.linalg.eigvalsh(Q) <= 0):
            raise np.linalg.LinAlgError("not an ellipsoid")
        # A lower-triangular with AᵀA = Q: reverse Cholesky (M = I in norm mode).
        J = np.eye(3)[::-1]
        L = J @ np.linalg.cholesky(J @ Q @ J).T @ J
        p = sfem.from_matrix(L, b).to_vector()
        p[sfem.MISALIGN] = 0.0
        return p
    except (np.linalg.LinAlgError, ValueError):
        return sfem.identity_vector()


def _check_capacity(raw: np.ndarray, mode: str) -> None:
    """NotIdentifiable unless the readings' distinct orientations (not rows) leave spare
    degrees of freedom for the parameters they determine (calibration/gate.py)."""
    why = capacity(raw, mode).refusal()
    if why:
        need = NORM_MIN_ORIENTATIONS if mode == "norm" else REFERENCE_MIN_ORIENTATIONS
        raise NotIdentifiable(f"{why}; record at least {need} distinct orientations")


def _as_n3(a: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values")
    return arr


def _sigma(sigma_g: np.ndarray | None, n: int) -> np.ndarray:
    if sigma_g is None:
        return np.ones((n, 3))
    sig = np.broadcast_to(np.asarray(sigma_g, dtype=float), (n, 3)).copy()
    bad = ~np.isfinite(sig) | (sig <= 0)
    if bad.all():
        return np.ones((n, 3))
    # Rows without a usable σ get the median of the others rather than infinite weight.
    sig[bad] = np.median(sig[~bad])
    return sig


def _covariance(
    jac_free: np.ndarray, chi2_red: float, free: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """cov = (JᵀWJ)⁻¹ · χ²_red on the free parameters; NaN for those not identifiable."""
    cov = np.full((sfem.N_PARAMS, sfem.N_PARAMS), np.nan)
    ident = free.copy()
    JtJ = jac_free.T @ jac_free
    sv = np.linalg.svd(jac_free, compute_uv=False)
    rank_ok = sv.size > 0 and sv[-1] > 1e-10 * sv[0]
    if rank_ok:
        inv = np.linalg.inv(JtJ) * max(chi2_red, 1e-300)
        idx = np.flatnonzero(free)
        cov[np.ix_(idx, idx)] = inv
    else:
        ident[:] = False
    return cov, ident


_UNSEEN = (
    "the positions' directions do not constrain it (nominal Jacobian condition > "
    f"{1 / STRUCTURAL_REL_TOL:.0f}); held at its nominal value"
)


def _structurally_undetermined(directions_g: np.ndarray, mode: str) -> tuple[str, ...]:
    """SFEM parameters the distinct orientations cannot determine (the gate decides)."""
    return undetermined_parameters(directions_g, mode)


def _why(ident: np.ndarray, *, norm_mode: bool = False) -> dict[str, str]:
    why: dict[str, str] = {}
    for name, ok in zip(sfem.PARAM_NAMES, ident, strict=True):
        if ok:
            continue
        if norm_mode and name in ("mx", "my", "mz"):
            why[name] = "a rotation of the sensor frame leaves |g| unchanged (norm mode)"
        else:
            why[name] = "the positions do not constrain it (rank-deficient Jacobian)"
    return why


# calibration/discrepancy/problem.py imports this name (helper big10b's file): it is
# sfem.vector_from_matrix, the one decomposition of A = M·C·S.
_decompose_batch = sfem.vector_from_matrix
