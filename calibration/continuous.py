"""Continuous-temperature fit: the SFEM (Eq. 1) at each reading's own die temperature.

The seed's ramp method (Sec. 1: "the ramp method assumes the sensor temperature
varies with time"). No steps: the 12 parameters are polynomials of the reading's
conditioned die temperature (Eq. 8, ``p_k(T) = Σ_j c_kj x^j``, x = (T − centre)/scale)
and ONE Levenberg–Marquardt fit (Eq. 7, ``scipy.optimize.least_squares``) over every
row finds all coefficients at once, with the analytic Jacobian of
:func:`calibration.sfem.forward_jacobian` chained through Eq. 8
(:func:`calibration.sfem.coefficient_jacobian`). Residuals as the per-temperature fits:
per axis ``A(U − b) − ref`` over σ (reference mode), ``|A(U − b)| − g`` over the
projected σ (norm mode, Eq. 3; M not identifiable).

* **Temperature**: per row, :func:`calibration.temperature_conditioning.condition_continuous`
  (plateau rows a line per plateau, ramp rows a local parabola in time): copes with a
  0.1 °C noisy, 0.11 °C-quantised channel.
* **Rate sensitivity**: while the die moves the output carries k·dT/dt
  (``temperature_rate``). When the recording has legs of both signs (up and down), k per
  axis (µg per °C/min) is fitted with the polynomials, so the model is the sensor at
  rest; one way only, k cannot be told from the bias, and the report says so. A
  direction-dependent offset (``thermal_hysteresis``) is ±h on the legs: at one ramp rate
  it looks exactly like k·rate and is absorbed by it (the report says that too).
* **Degree**: by held-out error. Rows are split into folds by 2 °C temperature bands
  (fold = the occupied band's rank mod 5); each degree 1…:data:`MAX_DEGREE` is refitted without each
  fold and scored by the fold's weighted residuals; the lowest held-out χ² wins (reported
  as an rms residual in µg). A degree is judged only where every fold's training rows
  determine its coefficients: before any refit, the linearised design of each fold's
  training rows (the all-row fit's Jacobian on them, columns scaled to unit norm) must
  have full rank with a condition number within :data:`CONDITION_LIMIT` (beyond it JᵀJ is
  singular in double precision), and each refit must converge. The first degree that
  fails either (or whose folds leave fewer residuals than coefficients) is not judged and
  the search stops there: the degree is chosen among the lower ones, and the model's notes
  name the degree, the fold and why. Higher degrees only add columns to the same rows (a
  design's condition number does not fall when a column is added).
* **Valid range**: the conditioned die temperatures covered, widened by the soak
  model's ``RANGE_MARGIN_C``.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import least_squares

from calibration import sfem
from calibration.errors import CalibrationError, NotIdentifiable
from calibration.fit import rmse_norm_ug
from calibration.plateaus import (
    MIN_POSITIONS_NORM,
    MIN_POSITIONS_REFERENCE,
    Segmentation,
    orientation_labels,
)
from calibration.recording import Recording
from calibration.temperature_conditioning import condition_continuous, rate_corrected_raw_g
from calibration.thermal import (
    JOINT_MAX_JACOBIAN,
    RANGE_MARGIN_C,
    SolverStatus,
    ThermalFit,
    ThermalModel,
    _row_sigma,
)

METHOD = "continuous"
MAX_DEGREE = 5
CV_BAND_C = 2.0
CV_FOLDS = 5
CV_FTOL = 1e-10  # a fold's refit has converged when χ² falls by less than this of itself
CV_MAX_ITER = 8
BAND_C = 10.0  # report bands
# A row is on a leg when its die moves faster than this (°C/min); a leg needs this many rows.
LEG_RATE_C_PER_MIN = 0.2
MIN_LEG_ROWS = 24
# The hysteresis direction turns where the die's rate changes sign; 0.02 °C/min is ~3× the
# conditioned rate's noise on a 0.1 °C channel, so noise alone does not flip it.
DIRECTION_RATE_C_PER_MIN = 0.02
AGREE_SIGMAS = 3.0
# Jacobian columns this close to dependent (condition number of the column-scaled Jacobian;
# JᵀJ's is its square, 1e16 ≈ 1/ε of double precision): the parameters are not determined.
# The orientations' check (degree 0, all rows) and each held-out fold's training rows.
CONDITION_LIMIT = 1e8


@dataclass
class _Solution:
    coeffs: np.ndarray  # (12, d+1)
    rate_gain_ug: np.ndarray | None  # (3,) µg per °C/min, or None when not fitted
    stderr: np.ndarray  # (12, d+1)
    rate_gain_se_ug: np.ndarray | None
    chi2_red: float
    success: bool
    hysteresis_ug: np.ndarray | None = None  # (3,) ±h by the last leg's direction
    hysteresis_se_ug: np.ndarray | None = None


class _Problem:
    """The rows of one continuous fit (weighted residuals and Jacobian of Eq. 1 via Eq. 8)."""

    def __init__(self, raw: np.ndarray, ref: np.ndarray | None, sigma: np.ndarray,
                 x: np.ndarray, terms: np.ndarray, g_local: float, free: np.ndarray) -> None:
        self.raw, self.ref, self.sigma, self.x = raw, ref, sigma, x
        # (N, m): each column z multiplies a per-axis offset g (µg) added to the raw output,
        # raw += z·g (rate: z = dT/dt in °C/min, g = k; hysteresis: z = ±1, g = h)
        self.terms, self.g_local = terms, g_local
        self.free = np.flatnonzero(free)
        self.fit_rate = terms.shape[1] > 0
        self.n_extra = 3 * terms.shape[1]

    def subset(self, rows: np.ndarray) -> _Problem:
        return _Problem(self.raw[rows], None if self.ref is None else self.ref[rows],
                        self.sigma[rows], self.x[rows], self.terms[rows], self.g_local,
                        np.isin(np.arange(sfem.N_PARAMS), self.free))

    def unpack(self, q: np.ndarray, n_coef: int) -> tuple[np.ndarray, np.ndarray]:
        c = np.zeros((sfem.N_PARAMS, n_coef))
        c[:, 0] = sfem.identity_vector()
        c[self.free] = q[: self.free.size * n_coef].reshape(self.free.size, n_coef)
        return c, q[self.free.size * n_coef:].reshape(-1, 3)

    def offsets_g(self, extra_ug: np.ndarray) -> np.ndarray:
        """(N,3) the extra terms' offsets of the raw output, g."""
        return self.terms @ extra_ug * 1e-6

    def _eval(self, q: np.ndarray, n_coef: int, jac: bool
              ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        c, extra = self.unpack(q, n_coef)
        V = np.vander(self.x, n_coef, increasing=True)
        raw = self.raw - self.offsets_g(extra)
        if not jac:
            return sfem.forward(V @ c.T, raw), None, V
        f, J = sfem.forward_jacobian(V @ c.T, raw)
        return f, J, V

    def residual(self, q: np.ndarray, n_coef: int) -> np.ndarray:
        f, _, _ = self._eval(q, n_coef, False)
        if self.ref is not None:
            return ((f - self.ref) / self.sigma).ravel()
        return (np.linalg.norm(f, axis=1) - self.g_local) / sfem.norm_sigma(f, self.sigma)

    def jacobian(self, q: np.ndarray, n_coef: int) -> np.ndarray:
        f, J, V = self._eval(q, n_coef, True)
        # ∂f/∂g_a = ∂f/∂b_a · z·10⁻⁶: an extra term enters Eq. 1 where the bias does
        cols = [sfem.coefficient_jacobian(J[:, :, self.free], V)]
        for m in range(self.terms.shape[1]):
            cols.append(J[:, :, sfem.BIAS] * (self.terms[:, m, None, None] * 1e-6))
        Jq = np.concatenate(cols, axis=-1)
        if self.ref is not None:
            return (Jq / self.sigma[:, :, None]).reshape(-1, Jq.shape[-1])
        return sfem.norm_jacobian(f, Jq) / sfem.norm_sigma(f, self.sigma)[:, None]

    def solve(self, n_coef: int, q0: np.ndarray) -> tuple[np.ndarray, Any]:
        sol = least_squares(self.residual, q0, jac=self.jacobian, args=(n_coef,), method="lm",
                            x_scale="jac")
        return sol.x, sol


def fit_continuous(
    recording: Recording,
    seg: Segmentation,
    *,
    g_local: float | None = None,
    rate_gain_ug_per_c_per_min: np.ndarray | None = None,
    max_degree: int = MAX_DEGREE,
    orientation: np.ndarray | None = None,
) -> ThermalFit:
    """Fit the continuous-temperature SFEM to a ramp (or mixed) recording (module docstring).

    The continuous solver behind :func:`calibration.fitting.fit`: to calibrate a
    recording, call that.

    ``orientation``: each row's distinct orientation as the gate clustered them
    (:func:`calibration.gate.distinct_orientations`' labels); None: clustered here.

    Raises :class:`NotIdentifiable` when the orientations visited do not determine the
    model, :class:`CalibrationError` when the recording has no temperature.
    """
    if not recording.has_temperature:
        raise CalibrationError("a continuous-temperature fit needs sensor_c or chamber_c")
    notes: list[str] = list(seg.notes)
    mode = "reference" if recording.has_reference else "norm"
    raw = recording.raw_g
    ref = recording.ref_g
    sigma = _row_sigma(recording, notes)
    if ref is not None:
        if g_local is not None:
            ref = ref / np.linalg.norm(ref, axis=1, keepdims=True) * g_local
        g_local = float(np.median(np.linalg.norm(ref, axis=1)))
    elif g_local is None:
        g_local = 1.0
    labels = orientation_labels(recording) if orientation is None else orientation
    _check_orientations(labels, mode)
    n_cols = int(np.sum(free_parameters(mode))) * (max_degree + 1) + 6
    if len(recording) * 3 * n_cols > JOINT_MAX_JACOBIAN:
        raise CalibrationError(
            f"{len(recording)} rows are too many for the continuous fit (a "
            f"{3 * len(recording)}x{n_cols} Jacobian): average the raw samples into one row "
            f"per capture (n and sd_x/sd_y/sd_z columns)")

    cond = condition_continuous(recording.t_s, recording.temperature_c(), seg.step)
    row_c, rate = cond.row_c, np.asarray(cond.row_rate_c_per_min, float)
    conditioning = f"{recording.temperature_source}: {cond.description}"
    legs = _legs(rate)
    fit_rate = rate_gain_ug_per_c_per_min is None and all(
        np.sum(legs == s) >= MIN_LEG_ROWS for s in (1, -1))
    if rate_gain_ug_per_c_per_min is not None:
        k_given = np.asarray(rate_gain_ug_per_c_per_min, float).reshape(3)
        raw = rate_corrected_raw_g(raw, rate, k_given)
        notes.append("temperature_rate corrected with the given k: "
                     + ", ".join(f"{v:.1f}" for v in k_given) + " µg per °C/min (x, y, z)")

    lo, hi = float(np.min(row_c)), float(np.max(row_c))
    centre, scale = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1.0)
    free = free_parameters(mode)
    direction = last_direction(_legs(rate, DIRECTION_RATE_C_PER_MIN))
    terms = np.column_stack([rate, direction]) if fit_rate else np.zeros((len(rate), 0))
    prob = _Problem(raw, ref, sigma, (row_c - centre) / scale, terms, g_local, free)
    _check_rank(prob, labels)

    # occupied bands numbered in order, so soak-like steps 10 °C apart spread over the folds
    # (band index mod 5 would put every step at a multiple of 10 °C into one fold)
    _, rank = np.unique(np.floor((row_c - lo) / CV_BAND_C).astype(int), return_inverse=True)
    folds = rank.ravel() % CV_FOLDS
    n_bands = int(rank.max()) + 1
    top = max(1, min(max_degree, n_bands - 1))
    scores: dict[int, float] = {}
    full: dict[int, np.ndarray] = {}
    q_prev = _start(prob)
    per_row = 3 if ref is not None else 1  # residuals per row (reference: x, y, z)
    # A degree is tried only when every fold's training rows outnumber its coefficients:
    # fewer residuals than unknowns has no least-squares answer (scipy's LM refuses it).
    fold_ids = np.unique(folds)
    n_train = np.array([int(np.sum(folds != f)) for f in fold_ids])
    n_train_res = int(n_train.min()) * per_row
    for d in range(1, top + 1):
        q0 = _raise_degree(q_prev, prob, d)
        if n_train_res <= q0.size:
            if d == 1:
                raise CalibrationError(
                    f"{len(recording)} rows on no temperature plateau are too few for the "
                    f"continuous fit: its degree-1 model has {q0.size} coefficients and "
                    f"choosing the degree by held-out error leaves {n_train_res} residuals "
                    "to fit them; soak until the die settles (each step a plateau: the step "
                    "fit needs far fewer rows) or measure more positions per step")
            k = int(fold_ids[np.argmin(n_train)]) + 1
            notes.append(f"degree {d} not judged: fold {k} of {fold_ids.size}'s training rows "
                         f"give {n_train_res} residuals for its {q0.size} coefficients; "
                         f"{_stopped_at(d)}")
            break
        q, sol_d = prob.solve(d + 1, q0)
        full[d] = q
        try:
            scores[d] = _heldout_chi2(prob, folds, q, sol_d, d + 1)
        except _NotJudged as why:
            notes.append(f"degree {d} not judged: {why}; {_stopped_at(d)}")
            break
        q_prev = q
    # no degree judged (degree 1's folds not determined): degree 1, the note says so
    degree = min(scores, key=lambda d: scores[d]) if scores else 1
    # as an rms held-out residual in µg (χ² per residual × the median σ): readable also when
    # the recording has no sd columns and every σ is 1 g
    sigma_ug = float(np.median(sigma)) * 1e6
    n_res = prob.residual(full[degree], degree + 1).size
    scores = {d: math.sqrt(s / n_res) * sigma_ug for d, s in scores.items()}
    q, sol = prob.solve(degree + 1, full[degree])
    solution = _solution(prob, q, sol, degree + 1)

    identifiable = free & np.all(np.isfinite(solution.stderr), axis=1)
    if solution.chi2_red > 2.0:
        notes.append(f"reduced chi-square {solution.chi2_red:.2f}: the model (Eq. 1 with "
                     "polynomials in temperature) does not describe these rows within their "
                     "noise; soakcal diagnose names what it leaves out")
    if not solution.success:
        notes.append("the continuous fit did not converge; its last iterate is used")
    model = ThermalModel(
        coeffs=solution.coeffs, t_centre_c=centre, t_scale_c=scale,
        valid_c=(lo - RANGE_MARGIN_C, hi + RANGE_MARGIN_C), mode=mode,
        identifiable=identifiable, coeff_stderr=solution.stderr, method=METHOD,
        temperature_source=recording.temperature_source,
        temperature_conditioning=conditioning, g_local=g_local, notes=list(notes),
        provenance={
            "input_file": os.path.basename(str(recording.path)), "rows": len(recording),
            "mode": mode, "method": METHOD, "degree_heldout_rms_ug": {
                str(d): round(s, 3) for d, s in scores.items()},
            "rate_gain_ug_per_c_per_min": None if rate_gain_ug_per_c_per_min is None else
            [float(v) for v in np.asarray(rate_gain_ug_per_c_per_min, float).reshape(3)],
            "rate_gain_fitted_ug_per_c_per_min": None if solution.rate_gain_ug is None
            else [float(v) for v in solution.rate_gain_ug],
            "hysteresis_fitted_ug": None if solution.hysteresis_ug is None
            else [float(v) for v in solution.hysteresis_ug],
            "created_utc": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat(),
        },
    )
    used_raw = raw - prob.offsets_g(prob.unpack(q, degree + 1)[1])
    from calibration.ramp_report import ramp_report  # it imports this module's constants

    report = ramp_report(model, recording, seg, used_raw, row_c, rate, legs, solution,
                         scores, notes, fit_rate)
    return ThermalFit(model, [], report, row_c, np.zeros(len(recording), int), notes,
                      used_raw, SolverStatus(bool(sol.success), str(sol.message), int(sol.nfev)))


class _NotJudged(Exception):
    """A degree's held-out error is not computed: one fold's training rows do not determine
    its coefficients, or the fold's refit does not converge (the message says which)."""


def _stopped_at(degree: int) -> str:
    """The degree search's stop, as the note ends it."""
    if degree == 1:
        return "degree 1 is used without a held-out score"
    if degree == 2:
        return "degree 1 is used, the only degree judged on every fold; higher degrees not tried"
    return (f"the degree is chosen among 1…{degree - 1}, the degrees judged on every fold; "
            "higher degrees not tried")


def _design_condition(J: np.ndarray) -> float:
    """Condition number of ``J`` with its columns scaled to unit norm (as ``x_scale="jac"``);
    inf when a column is zero or ``J`` is rank-deficient."""
    if J.shape[0] < J.shape[1] or not np.all(np.linalg.norm(J, axis=0) > 0):
        return math.inf
    return _scaled_condition(J)


def _scaled_condition(J: np.ndarray) -> float:
    """s_max / s_min of ``J`` with its columns scaled to unit norm (no zero column); inf
    when s_min is 0. The one test of :data:`CONDITION_LIMIT`, for the orientations
    (:func:`_check_rank`) and each held-out fold (:func:`_design_condition`)."""
    s = np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def _heldout_chi2(prob: _Problem, folds: np.ndarray, q: np.ndarray, sol: Any,
                  n_coef: int) -> float:
    """Σ over the folds of the fold's weighted residuals² at the fit of the other folds
    (module docstring, "Degree"); ``q``, ``sol``: the fit of every row at this degree.

    Every fold's training design is checked before any fold is refitted: the all-row fit's
    Jacobian on the training rows (the refit's linearisation at its start) with a condition
    number beyond :data:`CONDITION_LIMIT` does not determine the coefficients. Raises
    :class:`_NotJudged` for that fold, or for the first fold whose refit does not converge:
    no held-out error is scored from a fit that is not a minimum.
    """
    ids = np.unique(folds)
    per_row = sol.fun.size // prob.x.size  # residuals per row: 3 (reference), 1 (norm)
    # each fold's rows as the R of their QR: the training rows' design has the singular
    # values (and column norms) of the other folds' R stacked, a few rows per coefficient
    # instead of every training residual
    r_of = {f: np.linalg.qr(sol.jac[(np.flatnonzero(folds == f)[:, None] * per_row
                                     + np.arange(per_row)).ravel()], mode="r") for f in ids}
    trains = []
    for f in ids:
        train = np.flatnonzero(folds != f)
        cond = _design_condition(np.vstack([r_of[g] for g in ids if g != f]))
        if not cond <= CONDITION_LIMIT:
            raise _NotJudged(
                f"fold {f + 1} of {ids.size}'s training rows ({train.size} of {prob.x.size}) "
                f"do not determine its coefficients (their design's condition number "
                f"{cond:.1e} is above {CONDITION_LIMIT:.0e})")
        trains.append((f, train))
    total = 0.0
    for f, train in trains:
        q_f, lm = _refit_without(prob, train, q, sol, n_coef)
        if lm is not None and not lm.success:
            raise _NotJudged(
                f"fold {f + 1} of {ids.size}'s refit did not converge (Levenberg–Marquardt "
                f"stopped after {int(lm.nfev)} evaluations: {str(lm.message).rstrip('.')})")
        total += float(np.sum(prob.subset(np.flatnonzero(folds == f)).residual(
            q_f, n_coef) ** 2))
    return total


def _refit_without(prob: _Problem, train: np.ndarray, q: np.ndarray, sol: Any,
                   n_coef: int) -> tuple[np.ndarray, Any]:
    """The minimum of the ``train`` rows' χ², from the fit of every row (``q``), and the
    Levenberg–Marquardt result when that solve ran (None: Gauss–Newton converged).

    Gauss–Newton on the normal equations, started with the all-row fit's own Jacobian and
    residuals (``sol.jac``, ``sol.fun``: its rows are the train rows' at ``q``), iterated
    until χ² falls by less than :data:`CV_FTOL` of itself: the same minimum a
    Levenberg–Marquardt solve from ``q`` finds (the folds' start is already close to it:
    one fold of five is left out), without its QR factorisation per iteration and its
    first Jacobian. Where a step does not lower χ² or the normal equations are not
    positive definite, the LM solve runs from the last iterate.
    """
    per_row = sol.fun.size // prob.x.size  # residuals per row: 3 (reference), 1 (norm)
    idx = (train[:, None] * per_row + np.arange(per_row)).ravel()
    sub = prob.subset(train)
    J, r = sol.jac[idx], sol.fun[idx]
    chi2 = float(r @ r)
    for _ in range(CV_MAX_ITER):
        step = _normal_step(J, r)
        if step is None:
            break
        q_new = q + step
        r_new = sub.residual(q_new, n_coef)
        chi2_new = float(r_new @ r_new)
        if not chi2_new <= chi2 * (1.0 + CV_FTOL):
            break  # not a descent (or not finite): the damped solver's case
        if chi2 - chi2_new <= CV_FTOL * chi2_new:
            return (q_new if chi2_new <= chi2 else q), None
        q, r, chi2 = q_new, r_new, chi2_new
        J = sub.jacobian(q, n_coef)
    return sub.solve(n_coef, q)


def _normal_step(J: np.ndarray, r: np.ndarray) -> np.ndarray | None:
    """The Gauss–Newton step −(JᵀJ)⁻¹Jᵀr, columns scaled to unit norm (as ``x_scale="jac"``);
    None when JᵀJ is not positive definite (a column no train row constrains)."""
    A = J.T @ J
    d = np.sqrt(np.diag(A))
    if not np.all(d > 0):
        return None
    try:
        chol = cho_factor(A / np.outer(d, d))
    except np.linalg.LinAlgError:
        return None
    return -cho_solve(chol, (J.T @ r) / d) / d


def free_parameters(mode: str) -> np.ndarray:
    """The SFEM parameters a fit can see: all 12 in reference mode, M not in norm mode."""
    free = np.ones(sfem.N_PARAMS, bool)
    if mode == "norm":
        free[sfem.MISALIGN] = False
    return free


def _legs(rate_c_per_min: np.ndarray, threshold: float = LEG_RATE_C_PER_MIN) -> np.ndarray:
    """+1 heating, −1 cooling, 0 standing (|rate| below ``threshold``, °C/min)."""
    return np.where(rate_c_per_min > threshold, 1,
                    np.where(rate_c_per_min < -threshold, -1, 0))


def last_direction(legs: np.ndarray) -> np.ndarray:
    """The die's last excursion direction per row (±1): the leg's sign while moving, the
    previous leg's while standing; rows before the first leg arrived by the opposite
    excursion (a ramp that starts by heating from −40 °C got there by cooling)."""
    moving = np.flatnonzero(legs != 0)
    if not moving.size:
        return np.zeros(legs.size)
    idx = np.maximum.accumulate(np.where(legs != 0, np.arange(legs.size), -1))
    out = np.where(idx >= 0, legs[np.maximum(idx, 0)], -legs[moving[0]])
    return out.astype(float)


def _check_orientations(labels: np.ndarray, mode: str) -> None:
    need = MIN_POSITIONS_REFERENCE if mode == "reference" else MIN_POSITIONS_NORM
    have = int(np.unique(labels).size)
    if have < need:
        raise NotIdentifiable(
            f"the recording visits only {have} distinct orientation(s); a {mode}-mode "
            f"continuous fit needs at least {need}: sweep the schedule's positions "
            f"(e.g. the 24 of seed Table 1) over and over while the chamber ramps")


def _check_rank(prob: _Problem, labels: np.ndarray) -> None:
    """Refuse when the orientations visited do not determine the parameters (degree 0)."""
    q0 = np.r_[sfem.identity_vector()[prob.free], np.zeros(prob.n_extra)]
    J = prob.jacobian(q0, 1)
    norms = np.linalg.norm(J, axis=0)
    if np.any(norms == 0):
        names = [sfem.PARAM_NAMES[i] for i in prob.free] + ["k_x", "k_y", "k_z", "h_x", "h_y",
                                                            "h_z"]
        bad = [names[i] for i in np.flatnonzero(norms == 0)]
        raise NotIdentifiable(f"no reading constrains {', '.join(bad)}")
    if _scaled_condition(J) > CONDITION_LIMIT:
        raise NotIdentifiable(
            f"the {np.unique(labels).size} orientations visited do not "
            f"determine the SFEM parameters (they lie too close to a plane or a line): "
            f"sweep positions that span all three axes")


def _start(prob: _Problem) -> np.ndarray:
    """Degree-1 start: the identity, no temperature slope, no rate gain."""
    c = np.zeros((sfem.N_PARAMS, 2))
    c[:, 0] = sfem.identity_vector()
    return np.r_[c[prob.free].ravel(), np.zeros(prob.n_extra)]


def _raise_degree(q: np.ndarray, prob: _Problem, degree: int) -> np.ndarray:
    """The solution at a lower degree as a start for ``degree`` (new powers zero)."""
    nf = prob.free.size
    c = q[: q.size - prob.n_extra].reshape(nf, -1)
    out = np.zeros((nf, degree + 1))
    out[:, : min(c.shape[1], degree + 1)] = c[:, : degree + 1]
    return np.r_[out.ravel(), q[q.size - prob.n_extra:]]


def _solution(prob: _Problem, q: np.ndarray, sol: Any, n_coef: int) -> _Solution:
    coeffs, extra = prob.unpack(q, n_coef)
    dof = max(sol.fun.size - q.size, 1)
    chi2_red = float(np.sum(sol.fun**2) / dof)
    se_q = np.full(q.size, np.nan)
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * max(chi2_red, 1.0)
        se_q = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        pass
    stderr = np.full(coeffs.shape, np.nan)
    nf = prob.free.size
    stderr[prob.free] = se_q[: nf * n_coef].reshape(nf, n_coef)
    se_extra = se_q[nf * n_coef:].reshape(-1, 3)
    return _Solution(coeffs, extra[0] if prob.fit_rate else None, stderr,
                     se_extra[0] if prob.fit_rate else None, chi2_red, bool(sol.success),
                     extra[1] if prob.fit_rate else None,
                     se_extra[1] if prob.fit_rate else None)


def norm_rmse_ug(cal_g: np.ndarray, g_local: float) -> float:
    """Eq. 9's |g| RMSE (µg) of calibrated rows; NaN for none."""
    return rmse_norm_ug(cal_g, g_local) if cal_g.size else math.nan
