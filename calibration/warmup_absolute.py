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

from dataclasses import dataclass, field, replace

import numpy as np

from calibration import sfem
from calibration.gate import STRUCTURAL_REL_TOL, Orientations
from calibration.recording import Recording
from calibration.schedules import identifiability

# Gauss–Newton stops when no coefficient moves by more than this (in its own unit: g,
# 1 or rad per x^j): far below any MEMS accelerometer's noise.
STEP_TOL = 1e-12
MAX_ITERATIONS = 30
# A parameter whose nominal Jacobian column is below this fraction of the largest moves
# the residuals only through the few-degree offsets of measured directions (the same
# bound as the gate's component tolerance): it is not fitted at all.
VISIBLE_REL = 0.1
# Typical size of a held parameter (datasheets: sensitivity within 1-2 %, cross-axis and
# mounting within 5-10 mrad), by unit: how far it is moved to see what it does to the
# fitted ones (_with_held_spread).
HELD_SPREAD = {"1": 0.02, "rad": 0.01}
# A parameter determined no better than this (stated error at centre_c, by unit) is held:
# a typical sensor's own spread (datasheets: offsets within tens of mg, sensitivity within
# 1-2 %, axes within 10 mrad); a "fit" that loose says less than the datasheet.
LOOSE = {"g": 0.01, "1": 0.01, "rad": 0.01}
# A degree must lower the held-out RMS by this fraction to be preferred (as the warm-up's).
MIN_GAIN = 0.005


@dataclass(frozen=True)
class AbsoluteFit:
    """Parameters a few orientations determine, fitted absolutely (module docstring)."""

    mode: str  # "norm" (|g|, Eq. 3) | "reference" (Eq. 4)
    names: tuple[str, ...]  # fitted, in sfem.PARAM_NAMES order
    coeffs: np.ndarray  # (len(names), degree+1) in powers of x
    stderr: np.ndarray  # same shape
    degree: int
    residual_rms_g: float  # |f| − g (norm) or f − ref per axis (reference), RMS
    condition: float  # of the column-scaled coefficient Jacobian of ``names``
    # the largest change of a value at centre_c from what the data cannot tell (norm mode:
    # the readings across gravity as bias or as tilt; the held parameters at their
    # typical size), in its unit; included in ``stderr``
    ambiguity: float
    # (N,) each capture's residual at the solution: |f| − g, or |f − ref| (reference)
    capture_residual_g: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # determined in structure but only this loosely (stated error at centre_c, its unit):
    # not fitted (LOOSE)
    loose: dict[str, float] = field(default_factory=dict)


def absolute_part(captures: Recording, orientations: Orientations, x: np.ndarray,
                  coeffs: np.ndarray, top_degree: int, folds: np.ndarray,
                  rate_offset_g: np.ndarray | None, g_local: float) -> AbsoluteFit:
    """What a warm-up's orientations determine absolutely, fitted (module docstring).

    ``coeffs`` (12, d+1): the warm-up's model so far (each axis' bias change,
    everything else nominal): the parameters not determined keep it. The degree (0 …
    ``top_degree``) is chosen by held-out error over ``folds`` (0/1 per capture), as the
    bias change's. ``rate_offset_g`` (N,3): the warm-up's rate term at each capture,
    subtracted first. An empty ``names`` when the orientations determine nothing.
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
    free = visible(directions, mode)
    # Only a parameter that is fitted can be reported determined: directions a degree or
    # so apart (noisy captures of one face) pass the rank test for an angle (ayx) that
    # moves |g| at second order only, below VISIBLE_REL, so it is not among ``free``.
    names = tuple(n for n in identified(directions, mode) if n in free)
    empty = AbsoluteFit(mode, (), np.zeros((0, 1)), np.zeros((0, 1)), 0, float("nan"),
                        float("nan"), 0.0)
    if not names:
        return empty
    raw = captures.raw_g if rate_offset_g is None else captures.raw_g - rate_offset_g
    base = np.vander(x, coeffs.shape[1], increasing=True) @ coeffs.T
    degree = _choose_degree(raw, x, coeffs, free, names, top_degree, folds, g_local, ref)
    if mode == "reference":
        fit = fit_absolute(raw, x, coeffs, free, names, degree, g_local=g_local, ref_g=ref)
        if fit is None:
            return empty
        fit = _with_degree_spread(fit, raw, x, coeffs, free, top_degree, g_local, ref)
        return _without_loose(_with_held_spread(fit, raw, x, coeffs, free, g_local, ref))
    # Norm mode: across gravity an axis reads its bias plus gravity's component from any
    # tilt, and |g| sees that reading at second order ((25 mg)² / 2 = 0.3 mg). Which of
    # the two it is, |g| cannot tell: the estimate takes the reading across gravity as
    # that axis' bias (exact when the faces are opposite); the same fit with it taken as
    # tilt bounds the difference, added to the standard errors.
    across = _across_gravity_bias(raw - base[:, sfem.BIAS], orientations, names)
    as_bias = np.array(coeffs, float)
    as_bias[sfem.BIAS, 0] += across
    fit = fit_absolute(raw, x, as_bias, free, names, degree, g_local=g_local)
    if fit is None:
        return empty
    if np.any(across):
        as_tilt = fit_absolute(raw, x, coeffs, free, names, fit.degree, g_local=g_local)
        if as_tilt is None or as_tilt.degree != fit.degree:
            return empty
        ambiguity = np.abs(as_tilt.coeffs - fit.coeffs)
        fit = replace(fit, stderr=np.hypot(fit.stderr, ambiguity),
                      ambiguity=float(np.max(ambiguity[:, 0])))
    fit = _with_degree_spread(fit, raw, x, as_bias, free, top_degree, g_local, None)
    return _without_loose(_with_held_spread(fit, raw, x, as_bias, free, g_local, None))


def _without_loose(fit: AbsoluteFit) -> AbsoluteFit:
    """``fit`` without the parameters whose stated error exceeds :data:`LOOSE`."""
    loose = {n: float(se) for n, se in zip(fit.names, fit.stderr[:, 0], strict=True)
             if se > LOOSE[sfem.PARAM_UNITS[sfem.PARAM_NAMES.index(n)]]}
    if not loose:
        return fit
    keep = np.array([n not in loose for n in fit.names])
    return replace(fit, names=tuple(n for n in fit.names if n not in loose),
                   coeffs=fit.coeffs[keep], stderr=fit.stderr[keep], loose=loose)


def _with_degree_spread(fit: AbsoluteFit, raw: np.ndarray, x: np.ndarray,
                        coeffs: np.ndarray, free: tuple[str, ...], top_degree: int,
                        g_local: float, ref: np.ndarray | None) -> AbsoluteFit:
    """``fit`` with the change one degree more would make added to its standard errors.

    Held-out error picks the degree that predicts unseen captures best; where most
    captures sit near the end of a warm-up, a curvature it leaves out can still move the
    value at centre_c by several standard errors. The next degree's fit (where the data
    determine it) says by how much.
    """
    if fit.degree >= top_degree:
        return fit
    higher = fit_absolute(raw, x, coeffs, free, fit.names, fit.degree + 1,
                          g_local=g_local, ref_g=ref)
    if higher is None or higher.degree != fit.degree + 1:
        return fit
    change = np.abs(higher.coeffs[:, : fit.degree + 1] - fit.coeffs)
    return replace(fit, stderr=np.hypot(fit.stderr, change),
                   ambiguity=max(fit.ambiguity, float(np.max(change[:, 0]))))


def _with_held_spread(fit: AbsoluteFit, raw: np.ndarray, x: np.ndarray, coeffs: np.ndarray,
                      free: tuple[str, ...], g_local: float, ref: np.ndarray | None
                      ) -> AbsoluteFit:
    """``fit`` with the spread from the held parameters added to its standard errors.

    What the orientations determine, they determine given the held parameters: a held
    scale or angle moves a fitted misalignment or scale at second order (a 1 % scale
    times a 5 mrad angle is 50 µrad, several standard errors of a long warm-up). Each
    held scale and angle is moved by its typical size (:data:`HELD_SPREAD`), the fit
    repeated, and the changes added in quadrature.
    """
    shifts = []
    for k, name in enumerate(sfem.PARAM_NAMES[3:], start=3):
        if name in fit.names:
            continue
        moved = np.array(coeffs, float)
        moved[k, 0] += HELD_SPREAD[sfem.PARAM_UNITS[k]]
        refit = fit_absolute(raw, x, moved, tuple(n for n in free if n != name), fit.names,
                             fit.degree, g_local=g_local, ref_g=ref)
        if refit is not None and refit.degree == fit.degree:
            shifts.append(refit.coeffs - fit.coeffs)
    if not shifts:
        return fit
    spread = np.sqrt(np.sum(np.square(shifts), axis=0))
    return replace(fit, stderr=np.hypot(fit.stderr, spread),
                   ambiguity=max(fit.ambiguity, float(np.max(spread[:, 0]))))


def _choose_degree(raw: np.ndarray, x: np.ndarray, coeffs: np.ndarray,
                   free: tuple[str, ...], names: tuple[str, ...], top: int,
                   folds: np.ndarray, g_local: float, ref: np.ndarray | None) -> int:
    """The lowest degree no higher one beats by more than MIN_GAIN in held-out RMS."""
    totals = [heldout_rms_g(raw, x, coeffs, free, names, d, folds, g_local, ref)
              for d in range(top + 1)]
    degree = 0
    for d in range(1, top + 1):
        if np.isfinite(totals[d]) and totals[d] < totals[degree] * (1.0 - MIN_GAIN):
            degree = d
    return degree


def _across_gravity_bias(offset_g: np.ndarray, orientations: Orientations,
                         names: tuple[str, ...]) -> np.ndarray:
    """(3,) per axis whose bias is not determined: its mean reading (less the bias change)
    in the orientations where it lies across gravity (|direction component| < 0.5); 0 for
    the others."""
    out = np.zeros(3)
    labels = orientations.labels
    for a in range(3):
        if sfem.PARAM_NAMES[a] in names:
            continue
        across = np.flatnonzero(np.abs(orientations.directions[:, a]) < 0.5)
        if across.size:
            out[a] = float(np.mean([np.mean(offset_g[labels == o, a]) for o in across]))
    return out


def visible(directions_g: np.ndarray, mode: str) -> tuple[str, ...]:
    """SFEM parameters that move the residuals at first order at these directions (the
    nominal Jacobian's columns, :data:`VISIBLE_REL` of the largest or more): fitted together
    so that a combination the orientations do see (x up: b_x together with s_x) is not
    left in the residuals."""
    f, jac = sfem.forward_jacobian(sfem.identity_vector(), np.asarray(directions_g, float))
    j = sfem.norm_jacobian(f, jac) if mode == "norm" else jac.reshape(-1, sfem.N_PARAMS)
    norms = np.linalg.norm(j, axis=0)
    free = sfem.PARAM_NAMES if mode == "reference" else sfem.PARAM_NAMES[:9]
    return tuple(n for k, n in enumerate(sfem.PARAM_NAMES)
                 if n in free and norms[k] >= VISIBLE_REL * norms.max())


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
    if name in fit.loose:
        unit = sfem.PARAM_UNITS[sfem.PARAM_NAMES.index(name)]
        return (f"held at {at}: the {orientations.count} orientations "
                f"({orientations.names(limit=6)}) determine it only to ±{fit.loose[name]:.2g} "
                f"{unit}, more than a typical sensor's own spread")
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


def fit_absolute(raw_g: np.ndarray, x: np.ndarray, base_coeffs: np.ndarray,
                 free: tuple[str, ...], names: tuple[str, ...], degree: int, *,
                 g_local: float = 1.0, ref_g: np.ndarray | None = None) -> AbsoluteFit | None:
    """Fit ``free`` as polynomials of ``degree`` in ``x``; return ``names`` (module docstring).

    ``raw_g`` (N,3) capture means; ``x`` (N,) their scaled temperatures; ``base_coeffs``
    (12, D+1) every parameter's polynomial in x (``free`` ones are the start, the others
    stay); ``ref_g`` (N,3) reference mode's directions in g, None for norm mode. The
    combinations of ``free`` the data do not determine (relative singular value below
    :data:`calibration.gate.STRUCTURAL_REL_TOL`) stay at their start; ``names``, the
    determined ones, do not depend on them. A degree the data do not determine is
    lowered; None when not even a constant is.
    """
    keep = np.array([n in names for n in free])
    for d in range(degree, -1, -1):
        solved = _gauss_newton(raw_g, x, base_coeffs, free, keep, d, g_local, ref_g)
        if solved is None:
            continue  # these orientations' temperatures do not determine degree d
        coef, jc, r = solved
        scale = np.linalg.norm(jc, axis=0)
        scale[scale == 0] = 1.0
        _, sv, vt = np.linalg.svd(jc / scale, full_matrices=False)
        rank = int(np.sum(sv > STRUCTURAL_REL_TOL * sv[0]))
        s2 = float(np.sum(r ** 2)) / max(jc.shape[0] - rank, 1)
        v = vt[:rank].T / sv[:rank]
        cov = (v @ v.T) / np.outer(scale, scale) * s2  # pseudo-inverse covariance
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None)).reshape(coef.shape)
        per_capture = np.abs(r) if ref_g is None else np.linalg.norm(r.reshape(-1, 3), axis=1)
        return AbsoluteFit("norm" if ref_g is None else "reference", names, coef[keep],
                           se[keep], d, float(np.sqrt(np.mean(r ** 2))),
                           _condition(jc[:, np.repeat(keep, d + 1)]), 0.0, per_capture)
    return None


def heldout_rms_g(raw_g: np.ndarray, x: np.ndarray, base_coeffs: np.ndarray,
                  free: tuple[str, ...], names: tuple[str, ...], degree: int,
                  folds: np.ndarray, g_local: float = 1.0,
                  ref_g: np.ndarray | None = None) -> float:
    """RMS residual of the held-out captures (fit on one fold, judged on the other, both
    ways round; ``folds`` 2 is always fitted), g; NaN when a fold does not determine
    ``degree`` or no fold holds a capture out."""
    keep = np.array([n in names for n in free])
    errs = []
    for held in (0, 1):
        fit, test = folds != held, folds == held
        if not test.any():  # an empty temperature block: nothing to judge this way round
            continue
        ref_fit = None if ref_g is None else ref_g[fit]
        solved = _gauss_newton(raw_g[fit], x[fit], base_coeffs, free, keep, degree,
                               g_local, ref_fit)
        if solved is None:
            return float("nan")
        idx = np.array([sfem.PARAM_NAMES.index(n) for n in free], int)
        base = np.vander(x[test], base_coeffs.shape[1], increasing=True) @ base_coeffs.T
        _, r = _linearised(raw_g[test], np.vander(x[test], degree + 1, increasing=True), base,
                           idx, solved[0], g_local, None if ref_g is None else ref_g[test])
        errs.append(r)
    if not errs:
        return float("nan")
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e ** 2)))


def _gauss_newton(raw_g: np.ndarray, x: np.ndarray, base_coeffs: np.ndarray,
                  free: tuple[str, ...], keep: np.ndarray, d: int, g_local: float,
                  ref_g: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(coefficients of ``free`` (n, d+1), the coefficient Jacobian, residuals) at the
    solution; None when the kept parameters' degree-d columns are not determined."""
    raw = np.asarray(raw_g, float)
    idx = np.array([sfem.PARAM_NAMES.index(n) for n in free], int)
    base_params = np.vander(x, base_coeffs.shape[1], increasing=True) @ base_coeffs.T
    powers = np.vander(x, d + 1, increasing=True)
    coef = np.zeros((idx.size, d + 1))
    start = base_coeffs[idx, : d + 1]
    coef[:, : start.shape[1]] = start
    jc, r = _linearised(raw, powers, base_params, idx, coef, g_local, ref_g)
    kept = np.repeat(keep, d + 1)
    if jc.shape[0] <= jc.shape[1] or _condition(jc[:, kept]) * STRUCTURAL_REL_TOL > 1.0:
        return None
    for _ in range(MAX_ITERATIONS):
        step = _solve(jc, -r)
        coef = coef + step.reshape(coef.shape)
        jc, r = _linearised(raw, powers, base_params, idx, coef, g_local, ref_g)
        if np.max(np.abs(step)) < STEP_TOL:
            break
    return coef, jc, r


def _solve(jc: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Least squares with the columns scaled and the undetermined combinations cut."""
    scale = np.linalg.norm(jc, axis=0)
    scale[scale == 0] = 1.0
    step, *_ = np.linalg.lstsq(jc / scale, rhs, rcond=STRUCTURAL_REL_TOL)
    return step / scale


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
