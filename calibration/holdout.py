"""Honest figures for ``soakcal calibrate``: leave-one-out error and degrees of freedom.

An in-sample RMSE only says how well the fit bent to the readings it saw: with 10
positions and 9 parameters (the MPU-6050 set) it is 0.09 mg while a position the fit
did not see is off by more than 1 mg. So next to it ``calibrate`` reports

* ``loo_rmse_ug`` -- leave one position (one static interval) out: refit that step's
  SFEM (Eq. 1, fitted as Eq. 4–7 or Eq. 3, same weights and floor as the real fit)
  without it, predict it, and take the |g| error (Eq. 9) of the prediction; RMS over
  every position of every step. Reference mode also gives ``loo_rmse_vector_ug``.
* ``dof`` -- observations, fitted parameters and the spare degrees of freedom of the
  worst step (norm mode: one |g| per position, counted on distinct orientations
  (:func:`calibration.gate.distinct_orientations`) where fewer; reference mode: three
  components;
  hand-placed references: one |g| per position against the 9 parameters |g| sees,
  since the labels there are a prior, not a measurement).

With fewer than :data:`MIN_SPARE_DOF` spare degrees of freedom in a step the held-out
figure would come from an (almost) exactly determined fit: ``loo_rmse_ug`` is null
and a warning says why, on stderr and in the JSON ``warnings`` list.
"""

from __future__ import annotations

import math
import sys
from typing import Any, TextIO

import numpy as np

from calibration import gate
from calibration.errors import NotIdentifiable
from calibration.fit import FitResult, fit_norm, fit_reference
from calibration.placement import reference_tolerance_rad
from calibration.recording import Recording
from calibration.thermal import ThermalFit, _row_sigma

MIN_SPARE_DOF = 3
# Raw sample-per-row steps are averaged per position before the leave-one-out
# refits (one refit per position of 10⁵ rows would take minutes).
MAX_LOO_ROWS = 5000
# More folds than this in one step (e.g. a raw recording without a position column,
# where every row is its own position): no leave-one-out, and a warning says why.
MAX_LOO_FOLDS = 2000


def holdout_fields(rec: Recording, fit: ThermalFit, *, warn: TextIO | None = None
                   ) -> dict[str, Any]:
    """``rmse_ug``, ``loo_rmse_ug`` (or None), ``dof`` and ``warnings``; warnings to stderr."""
    warn = sys.stderr if warn is None else warn
    out = leave_one_out(rec, fit)
    for w in out["warnings"]:
        print(f"warning: {w}", file=warn)
    return out


def add_holdout(doc: dict[str, Any], rec: Recording, fit: ThermalFit) -> dict[str, Any]:
    """Add :func:`holdout_fields` to a ``calibrate --json`` document (warnings merged)."""
    held = holdout_fields(rec, fit)
    warnings = list(doc.get("warnings") or []) + held.pop("warnings")
    doc.update(held)
    doc["warnings"] = warnings
    return doc


def format_holdout(held: dict[str, Any]) -> str:
    """One line for the text report."""
    dof = held["dof"]
    loo = held["loo_rmse_ug"]
    loo_txt = "not given (too few spare degrees of freedom)" if loo is None else \
        f"{loo / 1e3:.4f} mg"
    return (f"|g| RMSE in-sample {held['rmse_ug'] / 1e3:.4f} mg, leave one position out "
            f"{loo_txt}; {dof['spare']} spare degrees of freedom ({dof['observations']} "
            f"observations, {dof['parameters']} parameters, worst step)")


def leave_one_out(rec: Recording, fit: ThermalFit) -> dict[str, Any]:
    """The held-out figures of :mod:`calibration.holdout` for one ``fit_campaign`` result."""
    mode = fit.model.mode
    g_local = fit.model.g_local
    # the rows the fit used (rate-corrected where it corrected them), so the refits
    # leave out exactly what the judged fit saw
    raw = rec.raw_g if fit.raw_used_g is None else fit.raw_used_g
    ref = rec.ref_g
    sigma = _row_sigma(rec, [])
    weighted = rec.sigma_g is not None
    tol = reference_tolerance_rad(rec) if ref is not None else None
    positions = rec.positions()
    warnings: list[str] = []
    in_sample: list[np.ndarray] = []
    norm_err: list[np.ndarray] = []
    vec_err: list[np.ndarray] = []
    worst: dict[str, int] | None = None
    loo_possible = True
    notes: list[str] = []

    for st in fit.steps:
        idx = np.flatnonzero(fit.row_step == st.step)
        in_sample.append(np.linalg.norm(st.fit.params.apply(raw[idx]), axis=1) - g_local)
        groups = positions[idx]
        names = np.unique(groups)
        n_params = int(np.sum(st.fit.identifiable))
        per_position = 1 if mode == "norm" else 3
        if tol is not None:
            # Hand-placed: the labels are priors, not data; only |g| (one per position)
            # tests the 9 parameters it sees (b, S, C).
            per_position, n_params = 1, min(n_params, 9)
        # Counted on distinct orientations (the gate's, calibration.gate): placements
        # repeated on one face say how well it repeats, not whether the model predicts a
        # direction it did not see (6 faces placed twice leave 0 spare for bias and scale).
        n_ori = gate.distinct_orientations(
            raw[idx], None if rec.sigma_g is None else rec.sigma_g[idx]).count
        dof = {"observations": per_position * min(names.size, n_ori), "parameters": n_params}
        dof["spare"] = dof["observations"] - n_params
        if worst is None or dof["spare"] < worst["spare"]:
            worst = dof
        if dof["spare"] < MIN_SPARE_DOF:
            where = (f"{names.size} positions" if n_ori >= names.size else
                     f"{names.size} positions, {n_ori} distinct orientations")
            counted = ("; counted on |g|, one per position: the hand-placed labels are a "
                       "prior of ref_tol_deg, not observations" if tol is not None else "")
            warnings.append(
                f"step {st.step}: {dof['spare']} spare degree(s) of freedom "
                f"({where}, {n_params} parameters, {mode} mode{counted}): the fit "
                f"can follow its readings, so its in-sample {st.fit.rmse_norm_ug / 1e3:.4f} mg "
                f"says little; no held-out figure is given (loo_rmse_ug null); measure "
                f"more positions")
            loo_possible = False
            continue
        if not loo_possible:
            continue
        if names.size > MAX_LOO_FOLDS:
            warnings.append(
                f"step {st.step}: {names.size} positions would need {names.size} refits; "
                "leave-one-out not computed (loo_rmse_ug null): give the rows a position "
                "column or average them per position")
            loo_possible = False
            continue
        X, R, S, T = raw[idx], None if ref is None else ref[idx], sigma[idx], \
            None if tol is None else tol[idx]
        if idx.size > MAX_LOO_ROWS and names.size < idx.size:
            X, R, S, T, groups = _position_means(X, R, S, T, groups, names)
            notes.append(f"step {st.step}: {idx.size} sample rows averaged per position "
                         "for the leave-one-out refits")
        try:
            for name in names:
                out = groups == name
                res = _refit(mode, X[~out], None if R is None else R[~out],
                             S[~out] if weighted else None,
                             None if T is None else T[~out], g_local)
                cal = res.params.apply(X[out])
                norm_err.append(np.linalg.norm(cal, axis=1) - g_local)
                if R is not None:
                    vec_err.append((cal - R[out]).ravel())
        except NotIdentifiable as exc:
            warnings.append(f"step {st.step}: leave-one-out not possible ({exc}); "
                            "loo_rmse_ug null")
            loo_possible = False

    def rms_ug(parts: list[np.ndarray]) -> float | None:
        if not parts:
            return None
        v = float(np.sqrt(np.mean(np.concatenate(parts) ** 2)) * 1e6)
        return round(v, 3) if math.isfinite(v) else None

    return {
        "rmse_ug": rms_ug(in_sample),
        "loo_rmse_ug": rms_ug(norm_err) if loo_possible else None,
        "loo_rmse_vector_ug": rms_ug(vec_err) if (loo_possible and ref is not None) else None,
        "loo_left_out": "one position (static interval) per refit, per step",
        "dof": worst or {"observations": 0, "parameters": 0, "spare": 0},
        "model_floor_ug": _floor_ug(fit),
        "loo_notes": notes,
        "warnings": warnings,
    }


def _refit(mode: str, raw: np.ndarray, ref: np.ndarray | None, sig: np.ndarray | None,
           tol: np.ndarray | None, g_local: float) -> FitResult:
    if mode == "norm":
        return fit_norm(raw, sig, g_local=g_local)
    return fit_reference(raw, ref, sig, g_local=g_local, ref_tol_rad=tol)


def _position_means(X: np.ndarray, R: np.ndarray | None, S: np.ndarray,
                    T: np.ndarray | None, groups: np.ndarray, names: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray,
                               np.ndarray | None, np.ndarray]:
    """Mean per position; σ of that mean from the rows' scatter (sd/√n)."""
    rows = [groups == k for k in names]
    Xm = np.array([X[m].mean(axis=0) for m in rows])
    Sm = np.array([X[m].std(axis=0, ddof=1) / np.sqrt(m.sum()) if m.sum() > 1
                   else S[m][0] for m in rows])
    Sm = np.where(np.isfinite(Sm) & (Sm > 0), Sm, np.median(S, axis=0))
    Rm = None if R is None else np.array([R[m].mean(axis=0) for m in rows])
    Tm = None if T is None else np.array([T[m].mean() for m in rows])
    return Xm, Rm, Sm, Tm, names.copy()


def _floor_ug(fit: ThermalFit) -> float | None:
    floors = [st.fit.model_floor_g for st in fit.steps]
    v = max((f for f in floors if math.isfinite(f)), default=math.nan)
    return round(v * 1e6, 3) if math.isfinite(v) else None
