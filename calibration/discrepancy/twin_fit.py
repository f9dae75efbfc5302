"""``soakcal twin fit``: a digital twin from one real campaign recording (docs/diagnosis.md §10).

The twin is the sensor model (SFEM with cubic parameters, seed Eq. 1 and 8), the die's lag
behind the chamber air, and the noise, estimated from one recording so that a simulated
campaign reproduces it:

0. the recording's diagnosis: the effects a twin carries are kept and their output taken
   out of the recording the base is fitted to (:mod:`calibration.discrepancy.twin_effects`);
1. ``calibrate``'s thermal fit (:func:`calibration.thermal.fit_campaign`) as the start;
2. on a recording whose only temperature is the chamber air, the die lag τ is profiled
   (the model's coefficients refitted at every τ by
   :func:`calibration.discrepancy.against.fit_shift`, the die history reconstructed by
   :func:`calibration.discrepancy.effects.thermal_lag.die_minus_air_c`); a recording with
   ``sensor_c`` already follows the die and the twin carries no lag;
3. the noise: per-axis sd of one reading (sd/√n pooled per step) and the temperature
   channel's noise.

The report says how close: per-plateau RMS of the recording minus the twin, over the noise.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from calibration.discrepancy import against as ag
from calibration.discrepancy import twin_effects
from calibration.discrepancy.twin_file import Twin
from calibration.recording import Recording
from calibration.thermal import fit_campaign

UG = 1e6


def fit_twin(rec: Recording, *, effects: bool = True, seed: int = 0
             ) -> tuple[Twin, dict[str, Any]]:
    """The twin of ``rec`` and a report of how close it comes (per plateau).

    ``effects``: the recording is diagnosed first (``diagnose``, ``seed``) and the effects it
    names that a twin carries go into the twin, its base fitted to the recording less their
    output (:mod:`calibration.discrepancy.twin_effects`); the report lists them and the
    findings left out, each with why.
    """
    carried: list[dict[str, Any]] = []
    omitted: list[dict[str, str]] = []
    diagnosis: dict[str, Any] = {"verdict": "not run"}
    if effects:
        carried, omitted, diagnosis = _diagnosed_effects(rec, seed)
    twin, report = _fit_base(twin_effects.without_effects(rec, carried))
    report.update({"recording": str(rec.path), "diagnosis": diagnosis,
                   "effects": [{k: e[k] for k in ("effect", "parameters", "parameter_sd",
                                                  "explanation")} for e in carried],
                   "effects_not_carried": omitted})
    return replace(twin, effects=carried), report


def _diagnosed_effects(rec: Recording, seed: int
                       ) -> tuple[list[dict[str, Any]], list[dict[str, str]], dict[str, Any]]:
    """What the diagnosis of ``rec`` names, split into carried and left out."""
    from calibration.discrepancy.diagnose import diagnose
    from calibration.errors import CalibrationError

    try:
        d = diagnose(rec, seed=seed)
    except (CalibrationError, ValueError, np.linalg.LinAlgError) as exc:
        return [], [], {"verdict": "not diagnosed", "reason": str(exc)}
    if d.cannot_judge:
        return [], [], {"verdict": "cannot judge", "reason": d.cannot_judge}
    carried, omitted = twin_effects.carried_effects(d)
    return carried, omitted, {"verdict": "mismatch" if d.mismatch else "consistent",
                              "findings": [f.effect for f in d.findings]}


def _fit_base(rec: Recording) -> tuple[Twin, dict[str, Any]]:
    """The base model, die lag and noise of the twin of ``rec`` (effects already out)."""
    notes: list[str] = []
    start = fit_campaign(rec).model
    twin0 = Twin(start)
    mode = "reference" if rec.has_reference else "norm"
    steps = rec.steps()
    air_c = ag._temperature(rec, start, notes)
    raw = rec.raw_g
    ref = rec.ref_g if mode == "reference" else None
    sigma = ag._sigma_g(rec, steps, start, raw, air_c, mode)
    if sigma is None:
        notes.append("no sd_* columns: noise taken from the residual")
        sigma = np.ones((len(rec), 3)) if mode == "reference" else np.ones(len(rec))
    fitted = ag._fitted_mask(start, mode, air_c, steps)
    dma = ag._lag_of(rec, replace(twin0, die_tau_s=0.0), notes)
    tau: float | None = None
    temp_c = air_c
    lag: dict[str, Any] = {}
    if dma is not None and len(np.unique(steps)) >= 2:
        lag = ag.rig_check(start, raw, ref, air_c, dma, 0.0, sigma, fitted, 0.01)
        tau = float(lag["tau_s"]) if lag["significant"] else 0.0
        temp_c = air_c + dma(tau)
    else:
        notes.append("no die lag fitted: the recording's temperature follows the die "
                     "(sensor_c) or there is one plateau")
    fit = ag.fit_shift(start, raw, ref, temp_c, sigma, fitted,
                       dtemp_dtau=ag.dtemp_dtau(dma, tau) if dma is not None and tau else None)
    se = start.coeff_stderr if start.coeff_stderr is not None else np.full(start.coeffs.shape,
                                                                             np.nan)
    model = replace(start, coeffs=start.coeffs + fit.delta,
                    coeff_stderr=np.where(fitted, fit.sd_recording, se),
                    provenance={**start.provenance, "twin_fit": str(rec.path)},
                    notes=list(start.notes) + (
                        [f"temperature is the die's, lagging the air by τ = {tau:.0f} s"]
                        if tau else []))
    resid = fit.residual
    if np.allclose(sigma, 1.0):
        sigma = np.full_like(sigma, float(np.std(resid)) or 1.0)
    sd_axis = (np.median(sigma, axis=0).tolist() if sigma.ndim == 2
               else [float(np.median(sigma))] * 3)
    temp_noise = _temperature_noise_c(rec)
    twin = Twin(model, tau, [float(v) for v in sd_axis], temp_noise, [],
                {"fitted_from": str(rec.path), "method": "soakcal twin fit"},
                _sample_sd_g(rec), _median_n(rec),
                die_tau_sd_s=lag.get("tau_sd_s") if lag.get("significant") else None)
    report = _closeness(resid, sigma, steps)
    report.update({"recording": str(rec.path), "mode": mode,
                   "die_tau_s": None if tau is None else round(tau, 1),
                   "die_lag_test": lag or None,
                   "noise": {"sd_ug": [round(v * UG, 2) for v in sd_axis],
                             "temperature_c": None if temp_noise is None
                             else round(temp_noise, 4)},
                   "notes": notes})
    return twin, report


def _sample_sd_g(rec: Recording) -> list[float] | None:
    """Per-sample sd of each axis (median of the sd_* columns), for the simulator's noise."""
    if not all(rec.has(c) for c in ("sd_x", "sd_y", "sd_z")):
        return None
    return [float(np.nanmedian(rec.columns[c])) for c in ("sd_x", "sd_y", "sd_z")]


def _median_n(rec: Recording) -> float | None:
    n = rec.columns.get("n")
    return None if n is None or not np.any(np.isfinite(n)) else float(np.nanmedian(n))


def _temperature_noise_c(rec: Recording) -> float | None:
    if not rec.has_temperature:
        return None
    from calibration.discrepancy.context import base_context
    from calibration.discrepancy.problem import temperature_noise_c

    ctx = base_context(rec, "reference", np.zeros((len(rec), 3)))
    return float(temperature_noise_c(ctx)[0])


def _closeness(resid: np.ndarray, sigma: np.ndarray, steps: np.ndarray) -> dict[str, Any]:
    """Per-plateau RMS of recording − twin (µg) and its ratio to the noise (1 = noise)."""
    per: list[dict[str, Any]] = []
    r2 = resid.reshape(resid.shape[0], -1)
    s2 = sigma.reshape(sigma.shape[0], -1)
    for s in np.unique(steps):
        m = steps == s
        rms = float(np.sqrt(np.mean(r2[m] ** 2)))
        noise = float(np.sqrt(np.mean(s2[m] ** 2)))
        per.append({"step": int(s), "rms_ug": round(rms * UG, 2),
                    "noise_ug": round(noise * UG, 2),
                    "rms_over_noise": round(rms / noise, 2) if noise > 0 else None})
    ratios = [p["rms_over_noise"] for p in per if p["rms_over_noise"] is not None]
    return {"per_plateau": per,
            "rms_ug": round(float(np.sqrt(np.mean(r2**2))) * UG, 2),
            "worst_plateau_rms_over_noise": max(ratios) if ratios else None,
            "median_plateau_rms_over_noise": float(np.median(ratios)) if ratios else None}


def report_text(report: dict[str, Any], out: str) -> str:
    lines = [f"twin of {report['recording']} ({report['mode']} mode) written to {out}"]
    tau = report["die_tau_s"]
    lines.append("  die lag: " + ("not fitted (temperature follows the die)" if tau is None
                                  else f"τ = {tau:.0f} s"))
    n = report["noise"]
    lines.append(f"  noise: {', '.join(f'{v:.2f}' for v in n['sd_ug'])} µg per reading (x, y, z)"
                 + (f", temperature {n['temperature_c']:.3f} °C" if n["temperature_c"] is not None
                    else ""))
    lines.append(f"  recording − twin: {report['rms_ug']:.2f} µg rms; per plateau, rms/noise "
                 f"median {report['median_plateau_rms_over_noise']:.2f}, worst "
                 f"{report['worst_plateau_rms_over_noise']:.2f}")
    for p in report["per_plateau"]:
        lines.append(f"    step {p['step']:>3}: {p['rms_ug']:8.2f} µg  "
                     f"(noise {p['noise_ug']:.2f} µg, ×{p['rms_over_noise']})")
    lines += _effect_lines(report)
    lines += [f"  note: {x}" for x in report["notes"]]
    return "\n".join(lines)


def _effect_lines(report: dict[str, Any]) -> list[str]:
    """What the twin carries from the recording's diagnosis, and what it leaves out."""
    diag = report.get("diagnosis") or {}
    if diag.get("verdict") in ("cannot judge", "not diagnosed"):
        return [f"  effects: none carried: the recording's diagnosis: {diag['verdict']} "
                f"({diag.get('reason', '')})"]
    if diag.get("verdict") == "not run":
        return ["  effects: not diagnosed (--no-effects)"]
    carried = report.get("effects") or []
    lines = [f"  effects carried: {twin_effects.summary(carried)}"
             + ("" if carried else " (the diagnosis names no effect a twin carries)")]
    lines += [f"    {e['effect']}: {e['explanation']}" for e in carried]
    lines += [f"  not carried: {o['effect']}: {o['why']}"
              for o in report.get("effects_not_carried") or []]
    return lines
