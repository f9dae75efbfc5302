"""``diagnose --against``: hold a given model or twin fixed and compare it with a recording.

docs/diagnosis.md §9. The given model's prediction is *not* refitted: its residual
``r = A(T)(raw − b(T)) − ref`` (seed Eq. 1 with the Eq. 8 polynomials; norm mode
``|f| − 1``) is what the recording says about it.

* The prediction is at the temperature ``calibrate`` conditions (a line per plateau), a
  parabola where a plateau curves beyond 3 standard errors (a short soak:
  :func:`calibration.temperature_conditioning.curved_plateaus_c`).
* ``parameter_shift``: the base parameters that moved. The shift δ of the model's
  polynomial coefficients is fitted to ``r`` by Gauss–Newton (the SFEM Jacobian of
  ``calibration.sfem`` times powers of T), and each coefficient is tested with
  ``z = δ / √(σ²_δ,recording + σ²_given)``: the given model's own stderr enters, because a
  model fitted on a recording of the same size carries about as much estimation noise as
  the shift fitted here (without it a perfect calibration would fail its own sensor). The
  recording's σ_δ is scaled up by the residual's reduced χ² when it is above 1 (an
  optimistic sd/√n cannot cause a false alarm), never down. Holm over the tested
  coefficients.
* What the refitted base still leaves (catalogue effects, ``unexplained``) comes from the
  ordinary :func:`~calibration.discrepancy.diagnose.diagnose` of the same recording.
* The verdict is the union of up to three tests (the shift, the refit diagnosis, the rig's
  die lag when the twin has one), each at α / (tests run): Bonferroni, so an unchanged
  sensor is called a mismatch with probability ≤ α as a whole (:func:`verdict_level`).
* The corrected twin is the given model with the shift applied; its held-out RMS is
  computed by whole plateaus (interior steps; 5 time blocks with < 4 steps), fitting the
  shift on the other plateaus, and compared with the given model on the *same* rows.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import stats as sps

from calibration import sfem
from calibration.discrepancy.context import AXES, plateau_directions
from calibration.discrepancy.heldout import plateau_folds
from calibration.discrepancy.level import ALPHA, N_NULL
from calibration.discrepancy.locate import _group_rms as locate_group_rms
from calibration.discrepancy.problem import pooled_sigma_g
from calibration.discrepancy.twin_file import Twin
from calibration.fit import NORM_FREE
from calibration.recording import Recording
from calibration.temperature_conditioning import condition_temperature, curved_plateaus_c
from calibration.thermal import ThermalModel

GN_ITERATIONS = 8
MIN_ROWS_PER_COEF = 2  # fewer rows than 2 per tested coefficient: cannot judge a shift
UG = 1e6
# Human names of the SFEM parameters (seed Eq. 1) for the sentences.
PARAM_WORDS = {"b": "bias", "s": "scale factor", "a": "non-orthogonality", "m": "misalignment"}


@dataclass
class ShiftFit:
    """The fitted coefficient shift and its uncertainty."""

    delta: np.ndarray  # (12, d+1) shift of the given model's coefficients (0 where not fitted)
    sd_recording: np.ndarray  # (12, d+1) σ of δ from this recording (× reduced χ²)
    sd_given: np.ndarray  # (12, d+1) stderr of the given model's coefficients (0 if absent)
    fitted: np.ndarray  # (12, d+1) bool: coefficients the shift was fitted for
    chi2_red: float
    residual: np.ndarray  # (N,3) or (N,) residual after the shift, g
    # The twin's effect coefficients refitted beside the base (twin_effects.py): their change
    # from the twin's and its σ from this recording; empty without effects.
    effect_delta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    effect_sd_recording: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class AgainstDiagnosis:
    recording: str
    against: str
    mode: str
    verdict: str  # "mismatch" | "consistent" | "cannot judge"
    reason: str
    rmse_given_ug: float
    rmse_shifted_ug: float
    noise_ug: float
    shift: dict[str, Any]
    findings: list[dict[str, Any]]
    heldout: dict[str, Any]
    located: dict[str, Any]
    refit: dict[str, Any] | None
    notes: list[str] = field(default_factory=list)
    corrected: Twin | None = field(default=None, repr=False)
    level: dict[str, Any] = field(default_factory=dict)  # verdict_level's split of α

    @property
    def mismatch(self) -> bool | None:
        return None if self.verdict == "cannot judge" else self.verdict == "mismatch"

    def to_dict(self) -> dict[str, Any]:
        return {
            "recording": self.recording, "against": self.against,
            "baseline": {"model": "given (held fixed)", "rmse_ug": _r(self.rmse_given_ug),
                         "noise_ug": _r(self.noise_ug), "mode": self.mode},
            "mismatch": self.mismatch, "verdict": self.verdict, "reason": self.reason,
            "findings": self.findings, "parameter_shift": self.shift,
            "rmse_after_shift_ug": _r(self.rmse_shifted_ug),
            "heldout": self.heldout, "located": self.located,
            "refit_diagnosis": self.refit, "level": self.level, "notes": self.notes,
        }

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, ensure_ascii=False)

    def report(self) -> str:
        lines = [f"recording {self.recording} against {self.against} ({self.mode} mode)",
                 f"given model held fixed: rms {self.rmse_given_ug:.2f} µg "
                 f"(noise {self.noise_ug:.2f} µg)"]
        if self.verdict == "cannot judge":
            lines.append(f"cannot judge: {self.reason}")
            return "\n".join(lines)
        lines.append(f"mismatch: {'yes' if self.mismatch else 'no'} ({self.reason})")
        for f in self.findings:
            hb, ha = f.get("heldout_rmse_before_ug"), f.get("heldout_rmse_after_ug")
            ho = f" (held-out {hb:.2f} → {ha:.2f} µg)" if hb is not None and ha is not None \
                else ""
            lines.append(f"  {f['effect']}: {f['explanation']}{ho}")
        if self.heldout.get("scheme"):
            lines.append(f"corrected twin, held out by {self.heldout['scheme']}: "
                         f"{self.heldout['rmse_given_ug']:.2f} → "
                         f"{self.heldout['rmse_corrected_ug']:.2f} µg on the same rows")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _sd_words(sd: float | None) -> str:
    return "" if sd is None else f" (σ {sd:.0f} s)"


def _r(v: float) -> float | None:
    return float(round(float(v), 2)) if np.isfinite(v) else None


# --- the pipeline ------------------------------------------------------------
def verdict_level(alpha: float, n_null: int, *, refit: bool, rig: bool) -> dict[str, Any]:
    """α of each of the verdict's tests, and the refit diagnosis' replicates.

    "mismatch" is the union of the tests run: the coefficient shift, the refit diagnosis
    (itself family-wise at its α) and the rig's die lag (a twin with a lag, a chamber-only
    recording). At α each, an unchanged sensor was flagged with probability up to 3α
    (measured on the second generator: docs/benchmarks.md); Bonferroni over them, each at
    α / k, holds α for the verdict whatever their dependence. The refit diagnosis splits its
    α / k over its own two tests, so its bootstrap needs 2k/α − 1 replicates to resolve it
    (level.py's rule at α / k): ``n_null`` is raised to that (beyond its resolution the
    diagnosis falls back on a Bonferroni bound, which holds the level but loses power).
    """
    tests = ["parameter_shift"] + (["refit_diagnosis"] if refit else []) + (
        ["rig_die_lag"] if rig else [])
    each = alpha / len(tests)
    return {"alpha": alpha, "method": f"Bonferroni over {len(tests)} test(s)",
            "tests": tests, "alpha_each": each,
            "n_null_refit": max(int(n_null), int(np.ceil(2.0 / each)) - 1) if refit else None}


def diagnose_against(recording: Recording, given: Twin, *, against: str = "", seed: int = 0,
                     n_null: int = N_NULL, alpha: float = ALPHA,
                     refit: bool = True) -> AgainstDiagnosis:
    """Compare ``recording`` with the given model/twin held fixed (docs/diagnosis.md §9)."""
    model = given.model
    notes: list[str] = []
    eff_x = eff_ctx = None
    if given.effects:
        # The twin's prediction is its base plus its effects (twin_effects.py): the recording
        # is compared less the effects' output, their coefficients refitted beside the base's
        # and tested with the twin's own σ, so what they explain is not a shift or a finding
        # and a change of their size is (issue 22).
        from calibration.discrepancy import twin_effects as tfx

        eff_ctx = tfx.context_of(recording)
        eff_x = tfx.effects_design(given.effects, eff_ctx)
        recording = tfx.less_raw(recording, eff_x @ tfx.coefficients(given.effects)[0])
        notes.append(f"the twin's effects ({tfx.summary(given.effects)}) are part of its "
                     "prediction: the recording is compared less their output, their "
                     "coefficients tested beside the base's")
    mode = "reference" if recording.has_reference else "norm"
    n = len(recording)
    steps = recording.steps()
    air_c = _temperature(recording, model, notes)
    raw = recording.raw_g
    ref = recording.ref_g if mode == "reference" else None
    die_minus_air = _lag_of(recording, given, notes)
    tau_given = given.die_tau_s if die_minus_air is not None else None
    temp_c = air_c if tau_given is None else air_c + die_minus_air(tau_given)
    fitted = _fitted_mask(model, mode, temp_c, steps)
    n_coef = int(fitted.sum())
    n_entries = n * (3 if mode == "reference" else 1)
    sigma = _sigma_g(recording, steps, model, raw, temp_c, mode)
    r0 = _residual(model.coeffs, model, raw, ref, temp_c)
    rms_given = float(np.sqrt(np.mean(r0**2)) * UG)
    noise_ug = float(np.sqrt(np.mean(sigma**2)) * UG) if sigma is not None else float("nan")
    if n_entries < MIN_ROWS_PER_COEF * n_coef + 2:
        return AgainstDiagnosis(
            str(recording.path), against, mode, "cannot judge",
            f"{n} reading(s) give {n_entries} residual(s), too few to test the "
            f"{n_coef} base coefficients (need at least {MIN_ROWS_PER_COEF * n_coef + 2})",
            rms_given, float("nan"), noise_ug, {}, [], {}, {}, None, notes)
    if sigma is None:
        notes.append("no sd_* columns: noise scale taken from the residual after the shift")
        sigma = np.ones_like(r0)
    fit = fit_shift(model, raw, ref, temp_c, sigma, fitted, effects_x=eff_x)
    findings: list[dict[str, Any]] = []
    tau = tau_given
    rig: dict[str, Any] = {}
    level = verdict_level(alpha, n_null, refit=refit,
                          rig=tau_given is not None and die_minus_air is not None)
    alpha_each = level["alpha_each"]
    if tau_given is not None and die_minus_air is not None:
        rig = rig_check(model, raw, ref, air_c, die_minus_air, tau_given, sigma, fitted,
                        alpha_each, given.die_tau_sd_s or 0.0, eff_x)
        if rig["significant"]:
            tau = rig["tau_s"]
            temp_c = air_c + die_minus_air(tau)
            fit = fit_shift(model, raw, ref, temp_c, sigma, fitted, effects_x=eff_x)
    if tau is not None and die_minus_air is not None and tau > 0:
        fit = fit_shift(model, raw, ref, temp_c, sigma, fitted,
                        dtemp_dtau=dtemp_dtau(die_minus_air, tau), effects_x=eff_x)
    shift = _shift_table(model, fit, alpha_each, temp_c,
                         None if eff_x is None else (given.effects, eff_ctx))
    heldout = _heldout(model, raw, ref, air_c, sigma, fitted, steps, recording.t_s,
                       recording.positions(),
                       None if tau is None else (die_minus_air, tau_given, tau), eff_x)
    if rig.get("significant"):
        findings.append({
            "effect": "thermal_lag", "axes": list(AXES), "where": {"steps": "all (lag after "
                                                                  "each step)"},
            "explanation": (f"Rig physics differs from the twin: the die lags the chamber air "
                            f"with τ = {rig['tau_s']:.0f} s{_sd_words(rig['tau_sd_s'])}, not "
                            f"the twin's {tau_given:.0f} s"),
            "parameters": {"tau_s": rig["tau_s"], "twin_tau_s": tau_given},
            "parameter_sd": {"tau_s": rig["tau_sd_s"]},
            "heldout_rmse_before_ug": heldout.get("rmse_given_ug"),
            "heldout_rmse_after_ug": heldout.get("rmse_corrected_ug"),
            "evidence": {"test": rig["test"], "p_value": rig["p_value"]},
            "confusers": [{"effect": "parameter_shift", "how_told_apart": "the shift is "
                           "refitted at every τ of the profile: τ is what the shift cannot "
                           "absorb"}],
        })
    if shift["significant"]:
        findings.append({
            "effect": "parameter_shift", "axes": shift["axes"],
            "where": _where(r0 - fit.residual if mode == "reference" else r0 - fit.residual,
                            steps, recording),
            "explanation": shift["sentence"], "parameters": shift["parameters"],
            "parameter_sd": shift["parameter_sd"],
            "rmse_before_ug": _r(rms_given),
            "rmse_after_ug": _r(float(np.sqrt(np.mean(fit.residual**2)) * UG)),
            "heldout_rmse_before_ug": heldout.get("rmse_given_ug"),
            "heldout_rmse_after_ug": heldout.get("rmse_corrected_ug"),
            "evidence": {"test": "z of each coefficient shift with the given model's stderr, "
                                 "Holm over the tested coefficients, at "
                                 f"α/{len(level['tests'])} = {alpha_each:.3g} (Bonferroni "
                                 "over the verdict's tests)",
                         "p_value": shift["p_family"]},
            "confusers": [{"effect": "a real new effect the base can mimic",
                           "how_told_apart": "the refit diagnosis below tests the catalogue "
                                             "effects after the refitted base"}],
        })
    refit_dict = None
    refit_mismatch = False
    if refit:
        from calibration.discrepancy.diagnose import diagnose

        rec_frame = recording
        if eff_x is not None and fit.effect_delta.size:
            # What the refitted base and the refitted effects leave: the effects' change
            # taken out too, or a twin's effect fitted on another recording is "found" again
            # for its own estimation error.
            rec_frame = tfx.less_raw(recording, eff_x @ fit.effect_delta)
        if tau is not None and die_minus_air is not None and tau > 0:
            # Why: the twin already holds the die lag; what the refitted base leaves must be
            # judged on the twin's die temperature, or the lag the twin carries is "found".
            cols = dict(rec_frame.columns)
            cols["chamber_c"] = cols["chamber_c"] + die_minus_air(tau)
            rec_frame = Recording.from_columns(cols)
            rec_frame.path = recording.path
            notes.append(f"the refit diagnosis uses the twin's die temperature (air + lag of "
                         f"τ = {tau:.0f} s)")
        d = diagnose(rec_frame, None, seed=seed, n_null=level["n_null_refit"],
                     alpha=alpha_each)
        refit_dict = d.to_dict()
        refit_mismatch = bool(d.mismatch)
        findings.extend(refit_dict["findings"])  # an ``unexplained`` finding included
    mismatch = bool(shift["significant"]) or refit_mismatch or bool(rig.get("significant"))
    if mismatch:
        parts = []
        if shift["significant"]:
            what = " and ".join(w for w, on in (("base parameters", shift["base_moved"]),
                                                ("the twin's effects", shift["effects_moved"]))
                                if on)
            parts.append(f"{what} moved (family p = {shift['p_family']:.3g})")
        if refit_mismatch:
            parts.append("the recording has structure the base model leaves out")
        if rig.get("significant"):
            parts.append(f"the die lag is {rig['tau_s']:.0f} s, not {tau_given:.0f} s")
        reason = "; ".join(parts)
    else:
        reason = (f"no coefficient moved beyond its σ (family p = {shift['p_family']:.3g}) and "
                  "the refitted base leaves nothing the tests can name"
                  if refit else f"no coefficient moved (family p = {shift['p_family']:.3g})")
    reason += f"; each test at α/{len(level['tests'])} = {alpha_each:.3g}"
    corrected = replace(given, model=_corrected_model(model, fit, against, recording),
                        effects=_corrected_effects(given.effects, fit),
                        die_tau_s=tau if tau is not None else given.die_tau_s,
                        provenance={**given.provenance, "corrected_against": str(recording.path)})
    if rig:
        notes.append(f"rig check: die lag profiled over τ, best {rig['tau_s']:.0f} s against "
                     f"the twin's {tau_given:.0f} s (p = {rig['p_value']:.3g})")
    located = _locate(r0, sigma, steps, recording)
    return AgainstDiagnosis(
        str(recording.path), against, mode, "mismatch" if mismatch else "consistent", reason,
        rms_given, float(np.sqrt(np.mean(fit.residual**2)) * UG), noise_ug, shift, findings,
        heldout, located, refit_dict, notes, corrected, level)


# --- the model's prediction ----------------------------------------------------
def _temperature(rec: Recording, model: ThermalModel, notes: list[str]) -> np.ndarray:
    """Per-row temperature conditioned as ``calibrate`` conditions it (per-step line fit),
    a plateau that curves in time significantly on its parabola
    (:func:`calibration.temperature_conditioning.curved_plateaus_c`)."""
    if not model.temperature_dependent:
        return np.zeros(len(rec))
    if not rec.has_temperature:
        raise ValueError("the given model depends on temperature but the recording has none")
    if model.temperature_source != rec.temperature_source and model.temperature_source != "none":
        notes.append(f"the model was fitted on {model.temperature_source}, the recording's "
                     f"thermal-model temperature is {rec.temperature_source}")
    steps = rec.steps()
    temp = curved_plateaus_c(rec.t_s, rec.temperature_c(), steps,
                   condition_temperature(rec.t_s, rec.temperature_c(), steps).row_c)
    lo, hi = model.valid_c or (-np.inf, np.inf)
    if np.any((temp < lo - 0.5) | (temp > hi + 0.5)):
        notes.append(f"the recording reaches {np.min(temp):.1f}…{np.max(temp):.1f} °C, beyond "
                     f"the model's valid {lo:g}…{hi:g} °C: the model is extrapolated there")
    return temp


def _params(coeffs: np.ndarray, model: ThermalModel, temp_c: np.ndarray) -> np.ndarray:
    x = model.x_of(temp_c) if model.temperature_dependent else np.zeros_like(temp_c)
    return np.vander(x, coeffs.shape[1], increasing=True) @ coeffs.T


def _residual(coeffs: np.ndarray, model: ThermalModel, raw: np.ndarray,
              ref: np.ndarray | None, temp_c: np.ndarray) -> np.ndarray:
    f = sfem.forward(_params(coeffs, model, temp_c), raw)
    if model.extensions:
        from calibration import extensions as ext

        f = ext.apply_extensions(model.extensions, raw, temp_c, f)
    return f - ref if ref is not None else np.linalg.norm(f, axis=1) - 1.0


def _fitted_mask(model: ThermalModel, mode: str, temp_c: np.ndarray,
                 steps: np.ndarray) -> np.ndarray:
    """Coefficients this recording can move: identifiable parameters × the powers its
    temperatures support (a recording at 3 temperatures cannot see a cubic's shift)."""
    n_temps = len({round(float(np.median(temp_c[steps == s])), 1) for s in np.unique(steps)})
    d = min(model.degree, max(n_temps - 1, 0)) if model.temperature_dependent else 0
    free = np.asarray(model.identifiable, bool).copy()
    if mode == "norm":
        free &= NORM_FREE
    mask = np.zeros(model.coeffs.shape, bool)
    mask[free, : d + 1] = True
    return mask


def _sigma_g(rec: Recording, steps: np.ndarray, model: ThermalModel, raw: np.ndarray,
             temp_c: np.ndarray, mode: str) -> np.ndarray | None:
    """σ of each residual entry: sd/√n pooled per step (the model's matrix ≈ identity)."""
    sig = pooled_sigma_g(rec, steps)
    if sig is None or not np.all(np.isfinite(sig) & (sig > 0)):
        return None
    if mode == "norm":
        f = sfem.forward(_params(model.coeffs, model, temp_c), raw)
        u = f / np.linalg.norm(f, axis=1)[:, None]
        return np.sqrt(np.sum((u * sig) ** 2, axis=1))
    return sig


# --- the shift ---------------------------------------------------------------
def fit_shift(model: ThermalModel, raw: np.ndarray, ref: np.ndarray | None, temp_c: np.ndarray,
              sigma: np.ndarray, fitted: np.ndarray, rows: np.ndarray | None = None,
              dtemp_dtau: np.ndarray | None = None,
              effects_x: np.ndarray | None = None) -> ShiftFit:
    """Gauss–Newton for the coefficient shift δ (weighted by 1/σ), on ``rows`` if given.

    ``dtemp_dtau`` (∂T/∂τ per row, °C/s): the temperature came from a profiled die lag τ;
    its column joins the covariance, so σ of δ is marginal over τ (a lag slightly off is
    partly absorbed by the tempcos; conditional σ would be too small).
    ``effects_x`` (N, 3, K): the raw output per unit coefficient of the twin's effects
    (``raw`` already taken less their output at the twin's coefficients); the change of
    those coefficients is fitted with δ (``effect_delta``), so it can be tested beside the
    base's own (issue 22: a twin's effect fitted on one recording is not exact either).
    """
    sel = np.ones(raw.shape[0], bool) if rows is None else rows
    w = 1.0 / sigma[sel]
    coeffs = model.coeffs.copy()
    cols = np.argwhere(fitted)  # (p,2): parameter, power
    x = model.x_of(temp_c[sel]) if model.temperature_dependent else np.zeros(int(sel.sum()))
    V = np.vander(x, model.coeffs.shape[1], increasing=True)
    Xe = None if effects_x is None or effects_x.shape[-1] == 0 else effects_x[sel]
    dc = np.zeros(0 if Xe is None else Xe.shape[-1])
    refs = None if ref is None else ref[sel]

    def jac_res() -> tuple[np.ndarray, np.ndarray]:
        raw_now = raw[sel] if Xe is None else raw[sel] - Xe @ dc
        return _jacobian(coeffs, model, raw_now, refs, temp_c[sel], V, cols, Xe)

    J = np.zeros((1, 1))
    r = np.zeros(1)
    p = cols.shape[0]
    for _ in range(GN_ITERATIONS):
        J, r = jac_res()
        Jw = J * w.reshape(-1)[:, None]
        scale = np.where(np.linalg.norm(Jw, axis=0) > 0, np.linalg.norm(Jw, axis=0), 1.0)
        step = np.linalg.lstsq(Jw / scale, -(r * w).reshape(-1), rcond=1e-12)[0] / scale
        coeffs[cols[:, 0], cols[:, 1]] += step[:p]
        dc += step[p:]
        if np.max(np.abs(step)) < 1e-13:
            break
    J, r = jac_res()
    Jw = J * w.reshape(-1)[:, None]
    if dtemp_dtau is not None:
        h = 0.01  # °C: the residual's slope in T, times ∂T/∂τ
        refs = None if ref is None else ref[sel]
        dr = (_residual(coeffs, model, raw[sel], refs, temp_c[sel] + h)
              - _residual(coeffs, model, raw[sel], refs, temp_c[sel] - h)) / (2 * h)
        dt = dtemp_dtau[sel] if dr.ndim == 1 else dtemp_dtau[sel][:, None]
        Jw = np.hstack([Jw, ((dr * dt) * w).reshape(-1, 1)])
    rw = (r * w).reshape(-1)
    dof = max(rw.size - Jw.shape[1], 1)
    chi2_red = float(rw @ rw) / dof
    scale = np.where(np.linalg.norm(Jw, axis=0) > 0, np.linalg.norm(Jw, axis=0), 1.0)
    G = (Jw / scale).T @ (Jw / scale)
    cov_all = np.linalg.pinv(G, rcond=1e-12, hermitian=True) / np.outer(scale, scale)
    cov = cov_all[: cols.shape[0], : cols.shape[0]]
    k = dc.size
    sd_eff = np.sqrt(np.clip(np.diag(cov_all)[p:p + k], 0, None) * max(chi2_red, 1.0))
    sd_rec = np.zeros(model.coeffs.shape)
    # Scaled up by χ²/dof when the residual exceeds sd/√n (an optimistic sd cannot raise an
    # alarm), never down: on the second generator's re-measurements χ²/dof was < 1 in 4 of
    # 5 (median 0.83, real vibration averages better than √n) while the temperature
    # coefficients' errors, shared by a plateau's readings, are not smaller for it; scaled
    # down, an unchanged sensor's shift passed α/2 in 5 of 450 (docs/benchmarks.md).
    sd_rec[cols[:, 0], cols[:, 1]] = np.sqrt(np.clip(np.diag(cov), 0, None)
                                             * max(chi2_red, 1.0))
    se = model.coeff_stderr
    sd_given = np.zeros(model.coeffs.shape) if se is None else np.nan_to_num(se, nan=0.0)
    return ShiftFit(coeffs - model.coeffs, sd_rec, sd_given, fitted, chi2_red, r, dc, sd_eff)


def _jacobian(coeffs: np.ndarray, model: ThermalModel, raw: np.ndarray, ref: np.ndarray | None,
              temp_c: np.ndarray, V: np.ndarray, cols: np.ndarray,
              effects_x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Residual and its Jacobian in the fitted coefficients: ∂f/∂p (seed Eq. 1) × x^j, and
    in the twin's effect coefficients (raw less ``effects_x`` @ c: ∂f/∂b · X, ∂f/∂b = −A)."""
    P = V @ coeffs.T
    f, jac = sfem.forward_jacobian(P, raw)
    if model.extensions:
        from calibration import extensions as ext

        f = ext.apply_extensions(model.extensions, raw, temp_c, f)
    Jp = sfem.coefficient_jacobian(jac, V, cols)  # (N,3,p)
    if effects_x is not None:
        Jp = np.concatenate([Jp, np.einsum("nij,njk->nik", jac[:, :, sfem.BIAS], effects_x)],
                            axis=2)
    if ref is not None:
        return Jp.reshape(-1, Jp.shape[2]), f - ref
    return sfem.norm_jacobian(f, Jp), np.linalg.norm(f, axis=1) - 1.0


def _shift_table(model: ThermalModel, fit: ShiftFit, alpha: float,
                 temp_c: np.ndarray, effects: tuple[list[dict[str, Any]], Any] | None = None
                 ) -> dict[str, Any]:
    """Per-coefficient z and Holm's family decision; words for what moved.

    ``effects`` (the twin's effects, their design context): their coefficients' changes
    (``fit.effect_delta``) join the family, each with the twin's own σ beside this
    recording's.
    """
    idx = np.argwhere(fit.fitted)
    if idx.size == 0:
        return {"significant": False, "p_family": 1.0, "coefficients": [], "axes": [],
                "parameters": {}, "parameter_sd": {}, "sentence": ""}
    sd = np.sqrt(fit.sd_recording**2 + fit.sd_given**2)
    z = np.array([fit.delta[k, j] / sd[k, j] if sd[k, j] > 0 else 0.0 for k, j in idx])
    z_eff = np.zeros(0)
    sd_eff = np.zeros(0)
    if effects is not None and fit.effect_delta.size:
        from calibration.discrepancy.twin_effects import coefficients

        sd_eff = np.sqrt(fit.effect_sd_recording**2 + coefficients(effects[0])[1] ** 2)
        z_eff = np.where(sd_eff > 0, fit.effect_delta / np.where(sd_eff > 0, sd_eff, 1.0), 0.0)
    n_base = z.size
    z = np.concatenate([z, z_eff])
    logp = np.log(2.0) + sps.norm.logsf(np.abs(z))
    m = z.size
    order = np.argsort(logp)
    holm = np.minimum(logp[order] + np.log(m - np.arange(m)), 0.0)
    holm = np.maximum.accumulate(holm)
    log_alpha = np.log(alpha)
    sig_sorted = np.cumprod(holm < log_alpha).astype(bool)
    significant = np.zeros(m, bool)
    significant[order] = sig_sorted
    p_family = float(np.exp(holm[0]))
    rows = []
    params: dict[str, float] = {}
    psd: dict[str, float] = {}
    words = []
    axes: set[str] = set()
    phys = model.t_scale_c ** np.arange(model.coeffs.shape[1])  # x-basis → per °C^j
    eff_names = [] if effects is None else [f"{e['effect']}.coef[{j}]" for e in effects[0]
                                            for j in range(len(e["coef"]))]
    for i in range(n_base, m):
        rows.append({"parameter": eff_names[i - n_base], "power": 0,
                     "shift": float(f"{fit.effect_delta[i - n_base]:.4g}"),
                     "sd": float(f"{sd_eff[i - n_base]:.3g}"), "unit": "g per unit regressor",
                     "z": round(float(z[i]), 2), "significant": bool(significant[i])})
    for i, (k, j) in enumerate(idx):
        name = sfem.PARAM_NAMES[k]
        unit, mult = _unit(sfem.PARAM_UNITS[k])
        unit_j = unit if j == 0 else f"{unit}/°C" if j == 1 else f"{unit}/°C^{j}"
        val = float(fit.delta[k, j] / phys[j] * mult)
        s = float(sd[k, j] / phys[j] * mult)
        rows.append({"parameter": name, "power": int(j), "shift": float(f"{val:.4g}"),
                     "sd": float(f"{s:.3g}"), "unit": unit_j, "z": round(float(z[i]), 2),
                     "significant": bool(significant[i])})
        if significant[i]:
            key = f"d_{name}{'' if j == 0 else f'_t{j}'}_{_key_unit(unit_j)}"
            params[key] = float(f"{val:.4g}")
            psd[key] = float(f"{s:.3g}")
            words.append(_words(name, j, val, s, unit_j))
            if name[-1] in AXES:
                axes.add(name[-1])
    centre = f"{model.t_centre_c:.1f} °C" if model.temperature_dependent else "any temperature"
    sentence = ""
    if words:
        sentence = ("The base parameters differ from the given model's (at " + centre + "): "
                    + "; ".join(words))
    if effects is not None and np.any(significant[n_base:]):
        from calibration.discrepancy.twin_effects import changed

        z_min = float(np.min(np.abs(z[n_base:][significant[n_base:]])))
        said = changed(effects[0], fit.effect_delta, fit.effect_sd_recording, z_min,
                       effects[1])
        sentence = "; ".join(s for s in [sentence, *said] if s)
        axes.update(AXES)
    return {"significant": bool(significant.any()), "p_family": float(f"{p_family:.3g}"),
            "base_moved": bool(significant[:n_base].any()),
            "effects_moved": bool(significant[n_base:].any()),
            "coefficients": rows, "axes": sorted(axes), "parameters": params,
            "parameter_sd": psd, "sentence": sentence,
            "chi2_per_dof_after_shift": round(fit.chi2_red, 3),
            "given_model_stderr": bool(np.any(fit.sd_given > 0))}


def _unit(u: str) -> tuple[str, float]:
    return {"g": ("µg", UG), "1": ("ppm", 1e6), "rad": ("µrad", 1e6)}[u]


def _key_unit(u: str) -> str:
    return u.replace("µ", "u").replace("/°C^", "_per_c").replace("/°C", "_per_c")


def _words(name: str, power: int, val: float, sd: float, unit: str) -> str:
    what = PARAM_WORDS.get(name[0], name)
    axis = name[1:] if name[0] in "bs" else name
    tempco = "" if power == 0 else " tempco" if power == 1 else f" T^{power} coefficient"
    if unit.startswith("µg") and power == 0 and abs(val) >= 1000:
        return f"{axis} {what} moved {val / 1000:+.2f} ± {sd / 1000:.2f} mg"
    return f"{axis} {what}{tempco} moved {val:+.3g} ± {sd:.2g} {unit}"


# --- the corrected twin and its held-out figure --------------------------------
def _corrected_model(model: ThermalModel, fit: ShiftFit, against: str,
                     rec: Recording) -> ThermalModel:
    se = np.where(fit.fitted, fit.sd_recording, np.nan_to_num(
        model.coeff_stderr if model.coeff_stderr is not None else np.full(model.coeffs.shape,
                                                                           np.nan), nan=np.nan))
    return replace(model, coeffs=model.coeffs + fit.delta, coeff_stderr=se,
                   provenance={**model.provenance, "corrected_by": "diagnose --against",
                               "given_model": against, "recording": str(rec.path)},
                   notes=list(model.notes) + ["coefficients shifted to the recording "
                                              f"{rec.path} by diagnose --against"])


def _corrected_effects(effects: list[dict[str, Any]], fit: ShiftFit) -> list[dict[str, Any]]:
    """The twin's effects with their coefficients refitted on this recording."""
    out, i = [], 0
    for e in effects:
        k = len(e["coef"])
        out.append({**e, "coef": [float(c + d) for c, d in
                                  zip(e["coef"], fit.effect_delta[i:i + k], strict=True)],
                    "coef_sd": [float(s) for s in fit.effect_sd_recording[i:i + k]]})
        i += k
    return out


def _heldout(model, raw, ref, temp_c, sigma, fitted, steps, t_s, positions,
             lag=None, effects_x: np.ndarray | None = None) -> dict[str, Any]:
    """RMS on held-out plateaus: the given model vs the shift fitted on the other plateaus.

    The folds are ``diagnose``'s (:func:`calibration.discrepancy.heldout.plateau_folds`, for
    the given model's degree in temperature): the end steps are never held out (a cubic does
    not extrapolate: that would test the polynomial, not the shift), nor an interior step
    whose others would determine the polynomial exactly; the same rows enter both figures.
    ``lag``: (die − air of τ, the twin's τ, the corrected τ): the given twin predicts at its τ, the
    corrected one at the corrected τ (τ itself is fitted on all rows: one scalar).
    """
    given_c = temp_c
    if lag is not None:
        dma, tau_g, tau_c = lag
        given_c, temp_c = temp_c + dma(tau_g), temp_c + dma(tau_c)
    step_temp_c = {int(s): float(np.median(temp_c[steps == s])) for s in np.unique(steps)}
    masks, scheme = plateau_folds(steps, step_temp_c, t_s, positions,
                                  degree=model.coeffs.shape[1] - 1)
    sq_g = sq_c = 0.0
    cnt = 0
    for m in masks:
        if m.all() or not m.any():
            continue
        fm = _fitted_mask(model, "reference" if ref is not None else "norm", temp_c[~m],
                          steps[~m]) & fitted
        f = fit_shift(model, raw, ref, temp_c, sigma, fm, rows=~m, effects_x=effects_x)
        shifted = replace(model, coeffs=model.coeffs + f.delta)
        raw_c = raw[m] if effects_x is None else raw[m] - effects_x[m] @ f.effect_delta
        r_g = _residual(model.coeffs, model, raw[m], None if ref is None else ref[m],
                        given_c[m])
        r_c = _residual(shifted.coeffs, model, raw_c, None if ref is None else ref[m],
                        temp_c[m])
        sq_g += float(np.sum(r_g**2))
        sq_c += float(np.sum(r_c**2))
        cnt += r_g.size
    if cnt == 0:
        return {}
    rg, rc = np.sqrt(sq_g / cnt) * UG, np.sqrt(sq_c / cnt) * UG
    return {"scheme": scheme, "rmse_given_ug": _r(rg), "rmse_corrected_ug": _r(rc),
            "improvement_percent": _r(100.0 * (1.0 - rc / rg)) if rg > 0 else None}


# --- rig physics: the die's lag ------------------------------------------------
def _lag_of(rec: Recording, twin: Twin, notes: list[str]):
    """T_die − T_air(τ) for this recording, or None when the twin's lag does not apply.

    The twin's model is in the die temperature on the air's scale (``twin fit`` on a
    chamber-only recording); a recording with ``sensor_c`` already follows the die.
    """
    if twin.die_tau_s is None:
        return None
    if rec.has("sensor_c") or not rec.has("chamber_c"):
        notes.append("the twin's die lag is not applied: the recording's temperature is the "
                     "sensor's own channel, which follows the die")
        return None
    from calibration.discrepancy.context import base_context
    from calibration.discrepancy.rig import die_minus_air_c

    ctx = base_context(rec, "reference", np.zeros((len(rec), 3)))
    cache: dict[float, np.ndarray] = {}

    def dma(tau_s: float) -> np.ndarray:
        key = round(float(tau_s), 6)
        if key not in cache:
            cache[key] = die_minus_air_c(ctx.t_s, ctx.steps, ctx.step_temp_c, tau_s,
                                         twin.air_tau_s, twin.ramp_c_per_min)
        return cache[key]

    return dma


# The reconstructed history (rig.py) recovers a simulated rig's τ within ~2 % (300 s: −2.1 %,
# 900 s: −0.5 %, 1800 s: −0.4 %, 20-min soaks); a twin's τ is not held to better than this.
TAU_RESOLUTION_REL = 0.03


def dtemp_dtau(dma, tau_s: float) -> np.ndarray:
    """∂T_die/∂τ per row (°C/s), central difference of the reconstructed history."""
    h = max(0.01 * tau_s, 1.0)
    return (dma(tau_s + h) - dma(max(tau_s - h, 0.0))) / (tau_s + h - max(tau_s - h, 0.0))


def rig_check(model: ThermalModel, raw, ref, air_c, dma, tau_given: float, sigma, fitted,
              alpha: float, tau_given_sd: float = 0.0,
              effects_x: np.ndarray | None = None) -> dict[str, Any]:
    """Profile the die lag τ (the shift refitted at each τ) against the twin's τ.

    Two conditions, both at α: the likelihood ratio of the best τ over the twin's (scaled by
    the residual variance at the best τ, χ²₁ tail, Bonferroni over the grid: the profile's
    search is paid for), and the difference of the two τ beyond their joint uncertainty
    (profile σ here, the twin's own σ, and :data:`TAU_RESOLUTION_REL` of the twin's τ).
    """
    from scipy.optimize import minimize_scalar

    from calibration.discrepancy.effects.thermal_lag import TAU_GRID_S

    def rss(tau_s: float) -> float:
        f = fit_shift(model, raw, ref, air_c + dma(tau_s), sigma, fitted, effects_x=effects_x)
        return float(np.sum((f.residual / sigma) ** 2))

    grid = sorted({0.0, *TAU_GRID_S, float(tau_given)})
    prof = np.array([rss(t) for t in grid])
    i = int(np.argmin(prof))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    best_t, best = grid[i], float(prof[i])
    if hi > lo:
        r = minimize_scalar(rss, bounds=(lo, hi), method="bounded", options={"xatol": 1.0})
        if r.fun < best:
            best_t, best = float(r.x), float(r.fun)
    n_res = raw.shape[0] * (3 if ref is not None else 1)
    dof = max(n_res - int(fitted.sum()) - 1, 1)
    s2 = max(best / dof, 1e-300)
    lr = max(rss(tau_given) - best, 0.0) / s2
    logp = float(sps.chi2.logsf(lr, 1)) + np.log(len(grid))
    h = max(0.02 * best_t, 1.0)
    curv = (rss(best_t + h) + rss(max(best_t - h, 0.0)) - 2 * best) / h**2
    tau_sd = float(np.sqrt(2.0 * s2 / curv)) if curv > 0 else float("nan")
    sd_diff = float(np.sqrt(np.nan_to_num(tau_sd, nan=0.0) ** 2 + tau_given_sd**2
                            + (TAU_RESOLUTION_REL * tau_given) ** 2))
    z = abs(best_t - tau_given) / sd_diff if sd_diff > 0 else np.inf
    logp_z = float(np.log(2.0) + sps.norm.logsf(z)) + np.log(len(grid))
    logp = max(logp, logp_z)
    return {"significant": bool(logp < np.log(alpha)), "tau_s": round(best_t, 1),
            "tau_sd_s": round(tau_sd, 1) if np.isfinite(tau_sd) else None,
            "p_value": float(f"{min(np.exp(logp), 1.0):.3g}"),
            "test": "likelihood ratio of the profiled die lag against the twin's (shift "
                    "refitted at each τ), χ²₁, and the τ difference over its joint σ; "
                    "Bonferroni over the τ grid"}


# --- where -------------------------------------------------------------------
def _group_rms(z: np.ndarray, keys: np.ndarray) -> dict[str, float]:
    """RMS of ``z`` per integer key, by one pass (locate's; a mask per key was O(rows²))."""
    return locate_group_rms(z, np.asarray(keys).astype(int))


def _locate(r: np.ndarray, sigma: np.ndarray, steps: np.ndarray,
            rec: Recording) -> dict[str, Any]:
    """RMS of the given model's residual over the noise, by axis, step, position, direction."""
    z = r / sigma
    zr = np.sqrt(np.mean(z.reshape(len(rec), -1) ** 2, axis=1))
    out: dict[str, Any] = {"units": "rms of the given model's residual / noise (1 = noise)"}
    if z.ndim == 2:
        out["by_axis"] = {AXES[a]: float(round(np.sqrt(np.mean(z[:, a] ** 2)), 2))
                          for a in range(3)}
    out["by_step"] = _group_rms(zr, steps)
    pos = rec.columns.get("position")
    if pos is not None and np.all(np.isfinite(pos)):
        out["by_position"] = _group_rms(zr, pos.astype(int))
    if rec.has_temperature:
        temp = rec.temperature_c()
        step_temp = {int(s): float(np.nanmedian(temp[steps == s])) for s in np.unique(steps)}
        d = plateau_directions(rec, steps, step_temp)
        out["by_direction"] = {{1: "heating", -1: "cooling", 0: "unknown"}[int(k)]:
                               float(round(np.sqrt(np.mean(zr[d == k] ** 2)), 2))
                               for k in np.unique(d)}
    return out


def _where(contrib: np.ndarray, steps: np.ndarray, rec: Recording) -> dict[str, Any]:
    """Steps and time span where the shift's contribution is at least half its largest."""
    per_row = np.sqrt(np.sum(contrib.reshape(len(rec), -1) ** 2, axis=1))
    top = float(per_row.max()) if per_row.size else 0.0
    big = per_row >= 0.5 * top if top > 0 else np.ones(len(rec), bool)
    return {"steps": sorted({int(s) for s in steps[big]}),
            "time_s": [float(rec.t_s[big].min()), float(rec.t_s[big].max())]}
