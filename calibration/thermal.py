"""Thermal model of the SFEM: each of the 12 parameters a cubic in temperature (Eq. 8).

    p_k(T) = c_k0 + c_k1·x + c_k2·x² + c_k3·x³,   x = (T − T_centre) / T_scale

Fitting a cubic in raw °C over −40…60 °C mixes columns of size 1 and 2·10⁵,
so the model works in the centred, scaled variable ``x`` (|x| ≤ 1 over the
calibrated range) and stores ``T_centre``/``T_scale`` with the coefficients.

:func:`fit_campaign` fits a whole soak campaign:

* ``method="per_step"`` -- the seed's procedure: Levenberg–Marquardt SFEM fit
  at each temperature step (Eq. 4–7, :mod:`calibration.fit`), then a weighted
  least-squares polynomial per parameter (Eq. 8), weights 1/stderr².
* ``method="joint"`` -- one LM over all readings with the polynomial
  coefficients as the unknowns (:mod:`calibration.thermal_joint`), started
  from ``per_step``. Measured better on held-out data (docs/calibration.md),
  so it is the default.

Reference mode when the recording has ``ref_*``, norm mode (Eq. 3; the
misalignment M is not identifiable) otherwise.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration import extensions as _ext
from calibration import metrics, sfem
from calibration.errors import CalibrationError, NotIdentifiable, OutOfRange
from calibration.fit import FitResult, fit_norm, fit_reference, rmse_norm_ug
from calibration.gate import check_thermal_fit
from calibration.placement import reference_tolerance_rad
from calibration.recording import Recording
from calibration.temperature_conditioning import condition_temperature, rate_corrected_raw_g
from calibration.thermal_joint import fit_joint

METHODS = ("per_step", "joint")
DEFAULT_METHOD = "joint"
MODEL_VERSION = "sfem-cubic-1"
# The valid range is the span of the step temperatures widened by this much: the
# noise of a step's mean temperature is ~0.01 °C, but a compensated run's own
# temperature reading scatters by ~0.1 °C and a cubic is smooth over 1 °C.
RANGE_MARGIN_C = 1.0
# Steps closer than this count as the same temperature when deciding the degree.
DISTINCT_C = 1.0
# Largest joint-fit Jacobian (entries, ~8 bytes each): raw sample-per-row recordings
# of 10⁵+ rows fall back to the per-step polynomials (said in the notes).
JOINT_MAX_JACOBIAN = 40_000_000


@dataclass
class StepParams:
    """One temperature step's SFEM fit as stored in the model (Eq. 1 parameters)."""

    step: int
    temperature_c: float
    n_positions: int
    params: np.ndarray  # (12,)
    stderr: np.ndarray  # (12,), NaN where not identifiable


@dataclass
class ThermalModel:
    """Cubic-in-temperature SFEM (Eq. 1 + Eq. 8), ready to compensate readings."""

    coeffs: np.ndarray  # (12, degree+1): parameter k = Σ_j coeffs[k, j] · x^j
    t_centre_c: float
    t_scale_c: float
    valid_c: tuple[float, float] | None  # None: temperature-independent (no temperature)
    mode: str  # "reference" | "norm"
    identifiable: np.ndarray  # (12,) bool
    coeff_stderr: np.ndarray | None = None  # (12, degree+1)
    method: str = DEFAULT_METHOD
    temperature_source: str = "sensor_c"  # "sensor_c" | "chamber_c" | "none"
    temperature_conditioning: str = ""
    g_local: float = 1.0
    steps: list[StepParams] = field(default_factory=list)
    extensions: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    provenance: dict[str, Any] = field(default_factory=dict)
    model_version: str = MODEL_VERSION
    # Which parameters the data determined and which were held, each with why
    # (calibration/gate.py decides; the model file and the report say it).
    fitted: dict[str, str] = field(default_factory=dict)
    held: dict[str, str] = field(default_factory=dict)
    # A warm-up's rate term k·dT/dt (calibration/warmup.py), or None: applied by
    # ``compensate`` (it needs the rows' times), not by :meth:`compensate` here.
    temperature_rate: dict[str, Any] | None = None
    # (12, degree+1, degree+1) covariance of each parameter's coefficients where the fit
    # gives it (a warm-up's bias), NaN elsewhere; not saved: the gate's slope check
    # (calibration.gate) reads it at fit time.
    coeff_cov: np.ndarray | None = None
    # The same with the choice of the model's degree in it (a warm-up's bias:
    # calibration.warmup._selection_cov), from which ``coeff_stderr`` is taken: the error
    # of the coefficients as the data know them. The gate judges the applied curve by
    # ``coeff_cov``. Not saved.
    coeff_cov_choice: np.ndarray | None = None

    @property
    def degree(self) -> int:
        return int(self.coeffs.shape[1] - 1)

    @property
    def temperature_dependent(self) -> bool:
        return self.valid_c is not None

    # --- evaluation -----------------------------------------------------
    def x_of(self, temperature_c: np.ndarray | float) -> np.ndarray:
        return (np.asarray(temperature_c, float) - self.t_centre_c) / self.t_scale_c

    def params_vector_at(
        self, temperature_c: np.ndarray | float, extrapolate: bool = False
    ) -> np.ndarray:
        """Parameter vector(s) at temperature(s): (12,) for a scalar, (N,12) for (N,)."""
        T = np.asarray(temperature_c, float)
        self.check_range(T, extrapolate)
        if not self.temperature_dependent or self.degree == 0:
            return np.broadcast_to(self.coeffs[:, 0], T.shape + (sfem.N_PARAMS,)).copy()
        V = np.vander(np.atleast_1d(self.x_of(T)).ravel(), self.degree + 1, increasing=True)
        P = V @ self.coeffs.T
        return P[0] if T.ndim == 0 else P.reshape(T.shape + (sfem.N_PARAMS,))

    def params_at(self, temperature_c: float, extrapolate: bool = False) -> sfem.SfemParams:
        """SFEM parameters (Eq. 1) at one temperature from the polynomials (Eq. 8)."""
        return sfem.SfemParams.from_vector(self.params_vector_at(float(temperature_c), extrapolate))

    def coefficients_at(
        self, temperature_c: float, extrapolate: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """(A 3×3, bias_g (3,)) with calibrated = A · (raw − bias) at this temperature.

        Raises :class:`OutOfRange` outside ``valid_c`` unless ``extrapolate``.
        """
        p = self.params_at(temperature_c, extrapolate)
        return p.matrix(), p.bias_g.copy()

    def compensate(
        self, raw_g: np.ndarray, temperature_c: np.ndarray | float, extrapolate: bool = False
    ) -> np.ndarray:
        """Calibrated, temperature-compensated specific force (N,3) in g.

        Each reading uses the parameters at its own temperature; the listed
        extensions (:mod:`calibration.extensions`) are applied after Eq. 1.
        """
        raw = np.atleast_2d(np.asarray(raw_g, float))
        if raw.shape[1] != 3:
            raise ValueError(f"raw_g must have shape (N, 3), got {raw.shape}")
        T = np.broadcast_to(np.asarray(temperature_c, float), (raw.shape[0],))
        P = self.params_vector_at(T, extrapolate)
        out = sfem.forward(P, raw)
        if self.extensions:
            out = _ext.apply_extensions(self.extensions, raw, T, out)
        return out

    def check_range(self, temperature_c: np.ndarray | float, extrapolate: bool = False) -> None:
        """Raise :class:`OutOfRange` (first offending value) unless all are in ``valid_c``."""
        if self.valid_c is None:
            return
        T = np.atleast_1d(np.asarray(temperature_c, float))
        if not np.all(np.isfinite(T)):
            raise CalibrationError(
                "this model depends on temperature, but a reading has no temperature"
            )
        if extrapolate:
            return
        lo, hi = self.valid_c
        bad = np.flatnonzero((lo > T) | (hi < T))
        if bad.size:
            raise OutOfRange(float(T[bad[0]]), self.valid_c)

    def first_out_of_range(self, temperature_c: np.ndarray) -> int | None:
        """Index of the first temperature outside ``valid_c`` (or not finite), else None."""
        if self.valid_c is None:
            return None
        T = np.asarray(temperature_c, float)
        bad = np.flatnonzero(~np.isfinite(T) | (self.valid_c[0] > T) | (self.valid_c[1] < T))
        return int(bad[0]) if bad.size else None

    def physical_coeffs(self) -> np.ndarray:
        """Coefficients in powers of (T − T_centre) in °C: c_kj / T_scale^j (units p/°C^j)."""
        return self.coeffs / self.t_scale_c ** np.arange(self.degree + 1)[None, :]


@dataclass
class StepResult:
    """One row of the seed's Table 6, plus the fit behind it."""

    step: int
    temperature_c: float  # conditioned (robust mean) step temperature; NaN if unknown
    setpoint_c: float | None
    fit: FitResult
    rmse_before_ug: float  # Eq. 9 on the raw readings
    rmse_measurement_ug: float  # Eq. 9 after this step's own SFEM fit
    rmse_polynomial_ug: float  # Eq. 9 after the thermal model (Eq. 8) at the rows' temperatures
    rmse_vector_measurement_ug: float | None = None  # reference mode: per-axis error rms
    rmse_vector_polynomial_ug: float | None = None
    temperature_noise_c: float | None = None


@dataclass(frozen=True)
class SolverStatus:
    """Whether the fits behind a model converged, the solver's message, its evaluations."""

    converged: bool
    message: str
    nfev: int


@dataclass
class ThermalFit:
    model: ThermalModel
    steps: list[StepResult]
    report: dict[str, Any]
    row_temperature_c: np.ndarray  # conditioned temperature per used row (NaN if none)
    row_step: np.ndarray  # step index per row (−1: row not used)
    notes: list[str] = field(default_factory=list)
    # The raw rows the fits used when they differ from the recording's (the
    # temperature_rate correction); None: the recording's own. Held-out refits
    # (calibration/holdout.py) must see the same rows as the fit they judge.
    raw_used_g: np.ndarray | None = None
    status: SolverStatus = SolverStatus(True, "", 0)


def fit_campaign(
    recording: Recording,
    *,
    method: str = DEFAULT_METHOD,
    degree: int = 3,
    g_local: float | None = None,
    rate_gain_ug_per_c_per_min: np.ndarray | None = None,
) -> ThermalFit:
    """Fit SFEM at each step and the cubic thermal model (Eq. 1, 4–8) to a recording.

    The step solver behind :func:`calibration.fitting.fit` (which decides, through the
    gate, that the recording has steps): to calibrate a recording, call that.

    ``g_local`` (units of standard gravity; :mod:`calibration.gravity`): the
    reference directions are scaled to it (reference mode) or |g| is fitted to
    it (norm mode). None: the references' median magnitude, or 1.0.

    ``rate_gain_ug_per_c_per_min`` (3,): the sensor's measured ``temperature_rate``
    gain k per axis; each row's k·dT/dt (dT/dt from the temperature conditioning's
    per-step line) is subtracted before the fits
    (:func:`calibration.temperature_conditioning.rate_corrected_raw_g`), so the model
    is the sensor's at rest. Needs a temperature in the recording.

    Raises :class:`calibration.gate.GateRefusal` for a result the gate refuses (did
    not converge, negative spare degrees of freedom counted on orientations, not
    physical) and :class:`NotIdentifiable` when no step can be fitted.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if degree < 0:
        raise ValueError(f"degree must be >= 0, got {degree}")
    notes: list[str] = []
    mode = "reference" if recording.has_reference else "norm"
    raw = recording.raw_g
    ref = recording.ref_g
    sigma = _row_sigma(recording, notes)
    if ref is not None:
        if g_local is not None:  # directions from the recording, magnitude the local gravity
            norm = np.linalg.norm(ref, axis=1, keepdims=True)
            ref = ref / np.where(norm > 0, norm, 1.0) * g_local
        g_local = float(np.median(np.linalg.norm(ref, axis=1)))
    elif g_local is None:
        g_local = 1.0
    method_requested = method
    ref_tol = reference_tolerance_rad(recording) if ref is not None else None
    if ref_tol is not None:  # hand-placed: calibration/placement.py, docs/fit-honesty.md
        notes.append("hand-placed references (ref_tol_deg): |g| fitted at full weight, "
                     "label directions as a prior of that angle")
        if method == "joint":  # the joint fit treats references as exact
            notes.append("joint fit not used: hand-placed references are fitted per step")
            method = "per_step"

    has_temp = recording.has_temperature
    if has_temp:
        steps = recording.steps()
        temp_src = recording.temperature_source
        cond = condition_temperature(recording.t_s, recording.temperature_c(), steps)
        row_c = cond.row_c
        conditioning = f"{temp_src}: {cond.description}"
        if cond.rejected_rows:
            conditioning += f"; {cond.rejected_rows} outlying temperature reading(s) ignored"
        if rate_gain_ug_per_c_per_min is not None:
            k = np.asarray(rate_gain_ug_per_c_per_min, float).reshape(3)
            raw = rate_corrected_raw_g(raw, cond.row_rate_c_per_min, k)
            notes.append("temperature_rate corrected: k·dT/dt subtracted from every row, k = "
                         + ", ".join(f"{v:.1f}" for v in k) + " µg per °C/min (x, y, z)")
    else:
        if rate_gain_ug_per_c_per_min is not None:
            raise CalibrationError("a rate-gain correction needs the die temperature in the "
                                   "recording")
        steps = np.zeros(len(recording), int)
        temp_src = "none"
        row_c = np.full(len(recording), np.nan)
        cond = None
        conditioning = "no temperature in the recording: one step at unknown temperature"
    notes.append(f"temperature conditioning: {conditioning}")
    recording.notes.append(f"thermal fit temperature conditioning: {conditioning}")
    if np.any(steps < 0):
        notes.append(f"{int(np.sum(steps < 0))} row(s) without a step index were not used")

    # --- per-step SFEM fits (Eq. 4–7) -----------------------------------
    fits: list[tuple[int, np.ndarray, FitResult]] = []
    for s in np.unique(steps[steps >= 0]):
        idx = np.flatnonzero(steps == s)
        try:
            if mode == "reference":
                fr = fit_reference(raw[idx], ref[idx], sigma[idx], g_local=g_local,
                                   ref_tol_rad=None if ref_tol is None else ref_tol[idx])
            else:
                fr = fit_norm(raw[idx], sigma[idx], g_local=g_local)
        except NotIdentifiable as exc:
            notes.append(f"step {int(s)} skipped: {exc}")
            continue
        if not fr.identifiable.any():
            notes.append(f"step {int(s)} skipped: its positions do not determine the model")
            continue
        fits.append((int(s), idx, fr))
    if not fits:
        raise NotIdentifiable(
            f"no temperature step has enough distinct orientations for an SFEM fit ({mode} "
            f"mode needs {'4' if mode == 'reference' else '10'} or more)"
        )
    step_temps = np.array(
        [cond.step_c.get(s, math.nan) if cond else math.nan for s, _, _ in fits]
    )
    identifiable = np.logical_and.reduce([fr.identifiable for _, _, fr in fits])

    # --- degree and temperature scaling ---------------------------------
    if has_temp:
        n_distinct = _count_distinct(step_temps, DISTINCT_C)
        used_degree = min(degree, n_distinct - 1)
        if used_degree < degree:
            notes.append(
                f"polynomial degree reduced from {degree} to {used_degree}: only "
                f"{n_distinct} distinct step temperature(s) (a degree-d polynomial needs d+1)"
            )
        lo, hi = float(np.min(step_temps)), float(np.max(step_temps))
        centre = 0.5 * (lo + hi)
        scale = max(0.5 * (hi - lo), 1.0)
        # The data's own span is always valid: a reading hotter than its step's mean is
        # still inside what the model was fitted on.
        row_t = recording.temperature_c()
        valid_c: tuple[float, float] | None = (
            min(lo - RANGE_MARGIN_C, float(np.nanmin(row_t))),
            max(hi + RANGE_MARGIN_C, float(np.nanmax(row_t))))
    else:
        used_degree, centre, scale, valid_c = 0, 0.0, 1.0, None
        if degree > 0:
            notes.append("polynomial degree 0: the recording has no temperature")

    coeffs, coeff_se, poly_chi2 = _per_step_polynomials(
        [fr for _, _, fr in fits], (step_temps - centre) / scale, used_degree, identifiable
    )
    joint_info: dict[str, Any] | None = None
    method_used = "per_step"
    used = np.concatenate([idx for _, idx, _ in fits])
    if method == "joint" and used.size * 3 * coeffs.size > JOINT_MAX_JACOBIAN:
        notes.append(
            f"joint fit skipped: {used.size} rows would need a "
            f"{used.size * 3}x{coeffs.size} Jacobian; the per-step polynomials are used"
        )
    elif method == "joint" and used_degree > 0:
        # Each step's model-error floor (fit.model_floor_g; 0 when its residuals are
        # noise) carries over to its rows, so the joint fit weighs as the steps did.
        floor = np.zeros(len(recording))
        for _, idx, fr in fits:
            floor[idx] = fr.model_floor_g if np.isfinite(fr.model_floor_g) else 0.0
        jr = fit_joint(
            raw[used], None if ref is None else ref[used],
            np.sqrt(sigma[used] ** 2 + floor[used, None] ** 2),
            (row_c[used] - centre) / scale, coeffs, identifiable, g_local=g_local,
        )
        coeffs, coeff_se, method_used = jr.coeffs, jr.coeff_stderr, "joint"
        if not jr.success:
            notes.append(f"joint fit did not converge ({jr.message}); its result is used")
        joint_info = {"chi2_red": jr.chi2_red, "nfev": jr.nfev, "success": jr.success,
                      "message": jr.message}
    elif method == "joint":
        notes.append("joint fit skipped: one temperature, nothing to fit across steps; "
                     "per-step result used")

    why_held = {n: why for _, _, fr in fits for n, why in fr.not_identifiable_why.items()}
    model = ThermalModel(
        fitted={n: "fitted" for n, ok in zip(sfem.PARAM_NAMES, identifiable, strict=True)
                if ok},
        held={n: "held at nominal: " + why_held.get(n, "not identifiable")
              for n, ok in zip(sfem.PARAM_NAMES, identifiable, strict=True) if not ok},
        coeffs=coeffs,
        t_centre_c=centre,
        t_scale_c=scale,
        valid_c=valid_c,
        mode=mode,
        identifiable=identifiable,
        coeff_stderr=coeff_se,
        method=method_used,
        temperature_source=temp_src,
        temperature_conditioning=conditioning,
        g_local=g_local,
        steps=[
            StepParams(s, float(T), fr.n_positions, fr.params.to_vector(), fr.stderr)
            for (s, _, fr), T in zip(fits, step_temps, strict=True)
        ],
        notes=list(notes),
        provenance={
            "input_file": os.path.basename(str(recording.path)),
            "rows": len(recording),
            "mode": mode,
            "method": method_used,
            "method_requested": method_requested,
            "degree_requested": degree,
            "rate_gain_ug_per_c_per_min": None if rate_gain_ug_per_c_per_min is None
            else [float(v) for v in np.asarray(rate_gain_ug_per_c_per_min, float).reshape(3)],
            "created_utc": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat(),
        },
    )

    # --- Table 6 columns --------------------------------------------------
    step_results: list[StepResult] = []
    setpoints = recording.columns.get("setpoint_c")
    for (s, idx, fr), T in zip(fits, step_temps, strict=True):
        cal = model.compensate(raw[idx], row_c[idx], extrapolate=True)
        sp = None
        if setpoints is not None and np.isfinite(setpoints[idx[0]]):
            sp = float(setpoints[idx[0]])
        vec_poly = None
        if ref is not None:
            vec_poly = float(np.sqrt(np.mean((cal - ref[idx]) ** 2)) * 1e6)
        step_results.append(StepResult(
            step=s,
            temperature_c=float(T),
            setpoint_c=sp,
            fit=fr,
            rmse_before_ug=fr.rmse_norm_before_ug,
            rmse_measurement_ug=fr.rmse_norm_ug,
            rmse_polynomial_ug=rmse_norm_ug(cal, g_local),
            rmse_vector_measurement_ug=fr.rmse_vector_ug,
            rmse_vector_polynomial_ug=vec_poly,
            temperature_noise_c=cond.step_noise_c.get(s) if cond else None,
        ))

    row_step = np.full(len(recording), -1)
    for s, idx, _ in fits:
        row_step[idx] = s
    report = _report(model, step_results, notes, poly_chi2, joint_info, recording)
    report["drift"] = _drift(model, recording, fits, row_c)
    failed = [f"step {s}: {fr.message}" for s, _, fr in fits if not fr.success]
    status = SolverStatus(
        converged=not failed and (joint_info is None or bool(joint_info["success"])),
        message="; ".join(failed) if failed else (
            f"joint fit: {joint_info['message']}" if joint_info is not None
            else f"{len(fits)} step fit(s) converged"),
        nfev=sum(int(fr.nfev) for _, _, fr in fits)
        + (0 if joint_info is None else int(joint_info["nfev"])))
    result = ThermalFit(model, step_results, report, row_c, row_step, notes,
                        raw if rate_gain_ug_per_c_per_min is not None else None, status)
    # The one gate (calibration/gate.py): no caller -- CLI, engine, benchmark -- gets a
    # model that did not converge, has no spare orientations, or is not physical.
    check_thermal_fit(result, recording)
    return result


# --- helpers ----------------------------------------------------------------
def _drift(
    model: ThermalModel,
    recording: Recording,
    fits: list[tuple[int, np.ndarray, FitResult]],
    row_c: np.ndarray,
) -> dict[str, Any] | None:
    """Drift before/after compensation at fixed orientation (groups = positions)."""
    if not model.temperature_dependent or len(fits) < 2:
        return None
    used = np.concatenate([idx for _, idx, _ in fits])
    raw = recording.raw_g[used]
    cal = model.compensate(raw, row_c[used], extrapolate=True)
    groups = recording.positions()[used]
    return metrics.drift_before_after(raw, cal, row_c[used], groups, model.g_local)


def _row_sigma(recording: Recording, notes: list[str]) -> np.ndarray:
    """Per-row, per-axis standard error (g): sd/√n where recorded, else equal weights."""
    n = len(recording)
    sig = recording.sigma_g
    if sig is None:
        notes.append("no sd_x/sd_y/sd_z columns: all readings weighted equally")
        return np.ones((n, 3))
    sig = sig.copy()
    bad = ~np.isfinite(sig) | (sig <= 0)
    if bad.all():
        return np.ones((n, 3))
    sig[bad] = np.median(sig[~bad])
    notes.append("weights 1/sigma^2 with sigma = sd/sqrt(n) of each averaged reading")
    return sig


def _count_distinct(values: np.ndarray, tol: float) -> int:
    v = np.sort(np.asarray(values, float))
    return int(1 + np.sum(np.diff(v) > tol)) if v.size else 0


def _per_step_polynomials(
    fits: list[FitResult], x: np.ndarray, degree: int, identifiable: np.ndarray
) -> tuple[np.ndarray, np.ndarray, list[float | None]]:
    """Weighted LS polynomial (Eq. 8) per parameter through the per-step estimates.

    Weights 1/stderr² (a step with an unusable stderr gets the median); the
    coefficient stderr is sqrt(diag((VᵀWV)⁻¹)) scaled by the reduced χ² when
    that exceeds 1 (the cubic not describing the steps within their errors
    inflates the uncertainty rather than hiding it).
    """
    P = np.array([fr.params.to_vector() for fr in fits])  # (S,12)
    SE = np.array([fr.stderr for fr in fits])
    ident_vec = sfem.identity_vector()
    coeffs = np.zeros((sfem.N_PARAMS, degree + 1))
    coeffs[:, 0] = ident_vec
    coeff_se = np.full_like(coeffs, np.nan)
    chi2: list[float | None] = [None] * sfem.N_PARAMS
    V = np.vander(np.nan_to_num(x), degree + 1, increasing=True)
    for k in range(sfem.N_PARAMS):
        if not identifiable[k]:
            continue
        se = SE[:, k].copy()
        ok = np.isfinite(se) & (se > 0)
        se[~ok] = np.median(se[ok]) if ok.any() else 1.0
        w = 1.0 / se
        c, *_ = np.linalg.lstsq(V * w[:, None], P[:, k] * w, rcond=None)
        coeffs[k] = c
        dof = P.shape[0] - (degree + 1)
        red = float(np.sum(((V @ c - P[:, k]) * w) ** 2) / dof) if dof > 0 else None
        chi2[k] = red
        try:
            cov = np.linalg.inv((V * w[:, None]).T @ (V * w[:, None]))
            coeff_se[k] = np.sqrt(np.diag(cov) * max(red or 1.0, 1.0))
        except np.linalg.LinAlgError:
            pass
    return coeffs, coeff_se, chi2


def _report(
    model: ThermalModel,
    steps: list[StepResult],
    notes: list[str],
    poly_chi2: list[float | None],
    joint_info: dict[str, Any] | None,
    recording: Recording,
) -> dict[str, Any]:
    """JSON-able summary: the model's header facts and the Table 6 rows."""

    def num(v: float | None, nd: int = 3) -> float | None:
        return None if v is None or not math.isfinite(v) else round(float(v), nd)

    positions = sorted({st.fit.n_positions for st in steps})
    return {
        "recording": os.path.basename(str(recording.path)),
        "rows": len(recording),
        "mode": model.mode,
        "method": model.method,
        "degree": model.degree,
        "positions_per_step": positions[0] if len(positions) == 1 else positions,
        "temperature_source": model.temperature_source,
        "temperature_conditioning": model.temperature_conditioning,
        "valid_c": list(model.valid_c) if model.valid_c else None,
        "g_local": model.g_local,
        "identifiable": {
            n: bool(v) for n, v in zip(sfem.PARAM_NAMES, model.identifiable, strict=True)
        },
        "fitted": dict(model.fitted),
        "held": dict(model.held),
        "polynomial_chi2_red": {
            n: num(c) for n, c in zip(sfem.PARAM_NAMES, poly_chi2, strict=True)
        },
        "joint_fit": joint_info,
        "notes": list(notes),
        "steps": [
            {
                "step": st.step,
                "temperature_c": num(st.temperature_c, 3),
                "setpoint_c": st.setpoint_c,
                "positions": st.fit.n_positions,
                "rmse_before_mg": num(st.rmse_before_ug / 1e3, 4),
                "rmse_polynomial_mg": num(st.rmse_polynomial_ug / 1e3, 4),
                "rmse_measurement_mg": num(st.rmse_measurement_ug / 1e3, 4),
                "rmse_vector_measurement_mg": num(
                    None if st.rmse_vector_measurement_ug is None
                    else st.rmse_vector_measurement_ug / 1e3, 4),
                "rmse_vector_polynomial_mg": num(
                    None if st.rmse_vector_polynomial_ug is None
                    else st.rmse_vector_polynomial_ug / 1e3, 4),
                "chi2_red": num(st.fit.chi2_red, 3),
                "temperature_noise_c": num(st.temperature_noise_c, 4),
            }
            for st in steps
        ],
    }
