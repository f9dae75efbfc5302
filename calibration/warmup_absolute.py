"""What a warm-up of a few orientations determines absolutely, and its fit.

A warm-up of 2–5 distinct orientations (:func:`calibration.gate.distinct_orientations`)
is too few for the whole SFEM (Eq. 1), but it may determine some of its 12 parameters
absolutely: ±z gives the z bias and the z scale (|g| seen from both sides), ±x, ±z the
same for x and z. Which ones is decided by the project's identifiability check
(:func:`calibration.schedules.identifiability`: the singular values of the Jacobian of
the orientations' design, relative :data:`calibration.gate.STRUCTURAL_REL_TOL`) on the
orientations' mean directions, in

* **norm mode** (Eq. 3, no reference directions): the residual of each capture is
  ``|f_i| − g``; the rotation M is invisible to |g|;
* **reference mode** (the recording has ``ref_x/ref_y/ref_z``, Eq. 4): three residuals
  ``f_i − ref_i`` per capture.

Those parameters are fitted as polynomials in each capture's own temperature (Eq. 8,
``p_k(T_i) = Σ_j c_kj x_i^j``) by Gauss–Newton on the exact model (the analytic
Jacobian of :func:`calibration.sfem.forward_jacobian`, chained through Eq. 8 by
:func:`calibration.sfem.coefficient_jacobian`); every other parameter keeps the value
given (nominal, or a warm-up's bias change). A degree the orientations' temperatures do
not determine (an orientation seen over only part of the range) is lowered until they
do. Standard errors are the least-squares covariance scaled by the residual variance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration import sfem
from calibration.gate import STRUCTURAL_REL_TOL, Orientations
from calibration.recording import Recording
from calibration.schedules import identifiability

# Gauss–Newton stops when no coefficient moves by more than this (in its own unit: g,
# 1 or rad per x^j): far below any MEMS accelerometer's noise.
STEP_TOL = 1e-12
MAX_ITERATIONS = 30


@dataclass(frozen=True)
class AbsoluteFit:
    """Parameters a few orientations determine, fitted absolutely (module docstring)."""

    mode: str  # "norm" (|g|, Eq. 3) | "reference" (Eq. 4)
    names: tuple[str, ...]  # fitted, in sfem.PARAM_NAMES order
    coeffs: np.ndarray  # (len(names), degree+1) in powers of x
    stderr: np.ndarray  # same shape
    degree: int
    residual_rms_g: float  # |f| − g (norm) or |f − ref| per axis (reference), RMS
    condition: float  # of the column-scaled coefficient Jacobian


def absolute_part(captures: Recording, orientations: Orientations, x: np.ndarray,
                  coeffs: np.ndarray, degree: int, rate_offset_g: np.ndarray | None,
                  g_local: float) -> AbsoluteFit:
    """What a warm-up's orientations determine absolutely, fitted (module docstring).

    ``coeffs`` (12, degree+1): the warm-up's model so far (each axis' bias change,
    everything else nominal): the parameters not determined keep it. ``rate_offset_g``
    (N,3): the warm-up's rate term at each capture, subtracted first. An empty
    ``names`` when the orientations determine nothing.
    """
    mode = "reference" if captures.has_reference else "norm"
    labels = orientations.labels
    if mode == "reference":
        ref = captures.ref_g
        sums = np.zeros((orientations.count, 3))
        np.add.at(sums, labels, ref)
        directions = sums / np.bincount(labels, minlength=orientations.count)[:, None]
    else:
        ref = None
        directions = orientations.directions * g_local
    names = identified(directions, mode)
    empty = AbsoluteFit(mode, (), np.zeros((0, 1)), np.zeros((0, 1)), 0, float("nan"),
                        float("nan"))
    if not names:
        return empty
    raw = captures.raw_g if rate_offset_g is None else captures.raw_g - rate_offset_g
    base = np.vander(x, degree + 1, increasing=True) @ coeffs.T
    return fit_absolute(raw, x, base, names, degree, g_local=g_local, ref_g=ref) or empty


def fitted_note(fit: AbsoluteFit, orientations: Orientations) -> str:
    """Why a parameter is fitted absolutely: by which orientations, in which mode."""
    how = ("|g| seen at each (norm mode, Eq. 3)" if fit.mode == "norm" else
           "their reference directions (reference mode, Eq. 4)")
    return (f"fitted absolutely: determined by the {orientations.count} orientations "
            f"({orientations.names(limit=6)}) and {how}; a polynomial of degree {fit.degree} "
            f"in each capture's temperature")


def held_note(name: str, fit: AbsoluteFit, orientations: Orientations) -> str:
    """Why a scale or angle is held at nominal although there are several orientations."""
    at = "1" if name in sfem.PARAM_NAMES[3:6] else "0"
    if fit.mode == "norm" and name in sfem.PARAM_NAMES[9:]:
        return (f"held at {at}: a rotation of the sensor frame leaves |g| unchanged (norm "
                f"mode, Eq. 3); it needs reference directions")
    return (f"held at {at}: the {orientations.count} orientations "
            f"({orientations.names(limit=6)}) do not determine it in {fit.mode} mode "
            f"(identifiability of their directions)")


def identified(directions_g: np.ndarray, mode: str) -> tuple[str, ...]:
    """SFEM parameters the orientations' directions (K,3) determine in ``mode``: the
    identifiability check with the gate's tolerances (norm mode: never M)."""
    check = identifiability(np.asarray(directions_g, float), mode,
                            rel_tol=STRUCTURAL_REL_TOL, component_tol=0.1)
    free = sfem.PARAM_NAMES if mode == "reference" else sfem.PARAM_NAMES[:9]
    return tuple(n for n in free if n not in check.undetermined)


def fit_absolute(raw_g: np.ndarray, x: np.ndarray, base_params: np.ndarray,
                 names: tuple[str, ...], degree: int, *, g_local: float = 1.0,
                 ref_g: np.ndarray | None = None) -> AbsoluteFit | None:
    """Fit ``names`` as polynomials of ``degree`` in ``x`` (module docstring).

    ``raw_g`` (N,3) capture means; ``x`` (N,) their scaled temperatures; ``base_params``
    (N,12) every parameter at each capture (the ones in ``names`` are replaced);
    ``ref_g`` (N,3) reference mode's directions in g, None for norm mode. None when
    not even a constant of each is determined.
    """
    raw = np.asarray(raw_g, float)
    idx = np.array([sfem.PARAM_NAMES.index(n) for n in names], int)
    mode = "norm" if ref_g is None else "reference"
    for d in range(degree, -1, -1):
        powers = np.vander(x, d + 1, increasing=True)
        coef = np.zeros((idx.size, d + 1))
        coef[:, 0] = sfem.identity_vector()[idx]
        jc, r = _linearised(raw, powers, base_params, idx, coef, g_local, ref_g)
        cond = _condition(jc)
        if jc.shape[0] <= jc.shape[1] or cond * STRUCTURAL_REL_TOL > 1.0:
            continue  # these orientations' temperatures do not determine degree d
        for _ in range(MAX_ITERATIONS):
            step, *_ = np.linalg.lstsq(jc, -r, rcond=None)
            coef = coef + step.reshape(coef.shape)
            jc, r = _linearised(raw, powers, base_params, idx, coef, g_local, ref_g)
            if np.max(np.abs(step)) < STEP_TOL:
                break
        dof = jc.shape[0] - jc.shape[1]
        s2 = float(np.sum(r ** 2)) / dof
        cov = np.linalg.pinv(jc.T @ jc) * s2
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None)).reshape(coef.shape)
        return AbsoluteFit(mode, names, coef, se, d, float(np.sqrt(np.mean(r ** 2))), cond)
    return None


def _linearised(raw: np.ndarray, powers: np.ndarray, base: np.ndarray, idx: np.ndarray,
                coef: np.ndarray, g_local: float, ref_g: np.ndarray | None
                ) -> tuple[np.ndarray, np.ndarray]:
    """The coefficient Jacobian and the residuals at ``coef`` (norm or reference mode)."""
    P = np.array(base, float, copy=True)
    P[:, idx] = powers @ coef.T
    f, jac = sfem.forward_jacobian(P, raw)
    if ref_g is None:
        r = np.linalg.norm(f, axis=1) - g_local
        j = sfem.norm_jacobian(f, jac)[:, idx]
    else:
        r = (f - ref_g).ravel()
        j = jac[:, :, idx].reshape(-1, idx.size)
        powers = np.repeat(powers, 3, axis=0)
    return sfem.coefficient_jacobian(j, powers), r


def _condition(jc: np.ndarray) -> float:
    """Condition number of the column-scaled Jacobian (inf when a column is zero)."""
    norms = np.linalg.norm(jc, axis=0)
    if np.any(norms == 0):
        return float("inf")
    sv = np.linalg.svd(jc / norms, compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
