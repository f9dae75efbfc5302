"""Static-interval detector settings chosen by evidence: leave-one-interval-out error.

``soakcal import`` finds static intervals with a variance threshold and trims their
ends (:func:`calibration.importers.detect_static_intervals`). Which threshold and
trim suit a recording depends on its rig and hand: on imu_tk's own Xsens data the
defaults (6×, 0.5 s) cost 20 % of leave-one-out error against imu_tk's settings.
This module tries a grid and keeps the setting whose intervals a norm-mode SFEM fit
(Eq. 3, 9 parameters, the weights ``calibrate`` uses: sd/√n with the model-error
floor) predicts best when each interval is left out.

Two guards keep the criterion honest:

* **Coverage.** A setting could lower the held-out error by dropping the hardest
  intervals; every interval is a position the calibration needs. Only settings
  keeping at least :data:`MIN_COVERAGE` of the largest interval count on the grid
  compete.
* **Enough intervals.** Leave-one-out needs ≥ 3 spare degrees of freedom after
  leaving one out (≥ 13 intervals); with fewer on every grid point the defaults are
  kept and the report says why.

The grid search uses the linearised leave-one-out (PRESS: r_i / (1 − h_ii) with the
weighted hat matrix of the fit's Jacobian), which equals the refit-based figure to
~10⁻⁴ mg on the real recordings (docs/realdata.md); the chosen setting's figure is
then the exact refit one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from calibration import sfem
from calibration.errors import NotIdentifiable
from calibration.fit import FitResult, fit_norm
from calibration.importers import (
    DetectorSettings,
    RawImport,
    find_intervals,
    intervals_to_recording,
)

THRESHOLD_GRID = (3.0, 4.0, 6.0, 8.0, 10.0, 15.0, 20.0)  # × initial-rest variance
TRIM_GRID_S = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
MIN_COVERAGE = 0.9
MIN_INTERVALS = 13  # 9 parameters + 3 spare + the one left out


@dataclass
class Candidate:
    threshold: float
    trim_s: float
    n_intervals: int
    loo_ug: float | None  # linearised leave-one-out |g| RMSE; None if not computable


@dataclass
class DetectorChoice:
    settings: DetectorSettings
    intervals: list[tuple[int, int]]
    chosen_by: str  # "leave-one-out" | "flags" | "defaults" | "sections"
    loo_ug: float | None  # exact refit leave-one-out of the chosen setting
    default_loo_ug: float | None  # the same for the format's defaults
    reason: str
    candidates: list[Candidate] = field(default_factory=list)

    def summary(self) -> str:
        st = self.settings
        if self.chosen_by == "sections":
            return f"static intervals: the labelled sections, trimmed {st.trim_s:g} s; " \
                f"{self.reason}"
        head = (f"static detection: threshold {st.threshold:g}x, trim {st.trim_s:g} s "
                f"({self.chosen_by})")
        if self.loo_ug is not None:
            head += f"; leave-one-interval-out |g| RMSE {self.loo_ug / 1e3:.4f} mg"
        if self.default_loo_ug is not None and self.chosen_by == "leave-one-out":
            head += f" (format defaults: {self.default_loo_ug / 1e3:.4f} mg)"
        return head + (f"; {self.reason}" if self.reason else "")


def choose_detector(raw: RawImport, base: DetectorSettings, *, fixed: frozenset[str] = frozenset()
                    ) -> DetectorChoice:
    """Best (threshold, trim) on the grid; ``fixed`` names the ones given by flags."""
    if raw.sections is not None:
        iv = find_intervals(raw, base)
        return DetectorChoice(base, iv, "sections", None, None,
                              "no detector, so no threshold to choose")
    if {"threshold", "trim_s"} <= fixed:
        iv = find_intervals(raw, base)
        return DetectorChoice(base, iv, "flags", exact_loo_ug(raw, iv), None, "")
    thresholds = (base.threshold,) if "threshold" in fixed else THRESHOLD_GRID
    trims = (base.trim_s,) if "trim_s" in fixed else TRIM_GRID_S
    found: list[tuple[Candidate, list[tuple[int, int]]]] = []
    for th in thresholds:
        for tr in trims:
            iv = find_intervals(raw, replace(base, threshold=th, trim_s=tr))
            found.append((Candidate(th, tr, len(iv), _press_ug(raw, iv)), iv))
    cands = [c for c, _ in found]
    most = max(c.n_intervals for c in cands)
    eligible = [(c, iv) for c, iv in found
                if c.loo_ug is not None and c.n_intervals >= MIN_COVERAGE * most]
    default_iv = find_intervals(raw, base)
    default_loo = exact_loo_ug(raw, default_iv)
    if not eligible:
        return DetectorChoice(
            base, default_iv, "defaults", default_loo, None,
            f"no grid setting gives the {MIN_INTERVALS} intervals leave-one-out needs "
            f"(most: {most})", cands)
    best, iv = min(eligible, key=lambda e: (e[0].loo_ug, -e[0].n_intervals))
    settings = replace(base, threshold=best.threshold, trim_s=best.trim_s)
    by = "leave-one-out" if not fixed else "leave-one-out, the other from the flags"
    return DetectorChoice(settings, iv, by, exact_loo_ug(raw, iv), default_loo,
                          f"{len(cands)} settings tried, {len(eligible)} kept >= "
                          f"{MIN_COVERAGE:.0%} of the {most} intervals", cands)


def exact_loo_ug(raw: RawImport, intervals: list[tuple[int, int]]) -> float | None:
    """Refit without each interval, predict its |g|: RMS in µg (None: too few intervals)."""
    if len(intervals) < MIN_INTERVALS:
        return None
    rec = intervals_to_recording(raw, intervals)
    X, S = rec.raw_g, rec.sigma_g
    err = []
    try:
        for i in range(X.shape[0]):
            keep = np.arange(X.shape[0]) != i
            res = fit_norm(X[keep], None if S is None else S[keep])
            err.append(float(np.linalg.norm(res.params.apply(X[i:i + 1])[0]) - res.g_local))
    except NotIdentifiable:
        return None
    return float(np.sqrt(np.mean(np.square(err))) * 1e6)


def _press_ug(raw: RawImport, intervals: list[tuple[int, int]]) -> float | None:
    if len(intervals) < MIN_INTERVALS:
        return None
    rec = intervals_to_recording(raw, intervals)
    try:
        res = fit_norm(rec.raw_g, rec.sigma_g)
    except NotIdentifiable:
        return None
    return press_ug(res, rec.raw_g, rec.sigma_g)


def press_ug(res: FitResult, raw_g: np.ndarray, sigma_g: np.ndarray | None) -> float | None:
    """Linearised leave-one-out of a norm-mode fit: RMS of r_i / (1 − h_ii), µg.

    h_ii is the leverage of reading i: the diagonal of J (JᵀJ)⁻¹ Jᵀ with J the
    weighted Jacobian of the |g| residuals (Eq. 3) in the free parameters, at the
    weights the fit used (sd/√n and its floor). Exact for a linear least-squares
    problem; the |g| residual is linear to ~10⁻² here.
    """
    free = res.identifiable
    if not free.any():
        return None
    f, jac = sfem.forward_jacobian(res.params.to_vector(), raw_g)
    norm = np.linalg.norm(f, axis=1)
    if sigma_g is None:
        s = np.ones(norm.size)
    else:
        floor = res.model_floor_g if np.isfinite(res.model_floor_g) else 0.0
        s = np.sqrt(sfem.norm_sigma(f, sigma_g) ** 2 + floor**2)
    J = sfem.norm_jacobian(f, jac[:, :, free]) / s[:, None]
    q, _ = np.linalg.qr(J)
    h = np.sum(q**2, axis=1)
    if np.any(h >= 1.0 - 1e-9):
        return None
    return float(np.sqrt(np.mean(((norm - res.g_local) / (1.0 - h)) ** 2)) * 1e6)
