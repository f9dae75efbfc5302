"""Report of a continuous-temperature (ramp) fit: the seed's Table 6 per temperature band.

A ramp has no steps, so Table 6's rows are temperature bands of :data:`BAND_C` °C
(of the conditioned die temperature): rows, distinct orientations, |g| RMSE before
and after calibration (Eq. 9, mg), vector RMSE after (reference mode), and, where the
band was crossed both heating and cooling, the fit residual's mean on each leg with
its standard error and whether the legs agree (difference within
``AGREE_SIGMAS`` standard errors). Then what the ramp identified and what it could
not (:func:`identified`).
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from calibration import sfem
from calibration.continuous import AGREE_SIGMAS, BAND_C, METHOD, MIN_LEG_ROWS, norm_rmse_ug
from calibration.plateaus import (
    MIN_POSITIONS_NORM,
    MIN_POSITIONS_REFERENCE,
    Segmentation,
    orientation_labels,
)
from calibration.recording import Recording
from calibration.thermal import ThermalFit, ThermalModel


def ramp_report(model: ThermalModel, rec: Recording, seg: Segmentation, raw_g: np.ndarray,
                row_c: np.ndarray, rate_c_per_min: np.ndarray, legs: np.ndarray,
                solution: Any, scores: dict[int, float], notes: list[str],
                fit_rate: bool) -> dict[str, Any]:
    """JSON-able report (``calibrate --json``) of a continuous fit."""
    cal = model.compensate(raw_g, row_c, extrapolate=True)
    ref = rec.ref_g
    if ref is not None:
        resid = cal - ref / np.linalg.norm(ref, axis=1, keepdims=True) * model.g_local
    else:
        resid = (np.linalg.norm(cal, axis=1) - model.g_local)[:, None]
    orient = orientation_labels(rec)
    need = MIN_POSITIONS_REFERENCE if model.mode == "reference" else MIN_POSITIONS_NORM
    bands = []
    for m, band in temperature_bands(row_c, raw_g, cal, model.g_local, orient):
        band |= {
            "rmse_vector_after_mg": None if ref is None else
            _r(float(np.sqrt(np.mean(resid[m] ** 2))) * 1e3),
            "mean_rate_c_per_min": _r(float(np.mean(rate_c_per_min[m])), 3),
        }
        band["legs"] = _legs_agreement(resid, m, legs)
        band["determined_here"] = band["positions"] >= need
        bands.append(band)
    return {
        "recording": os.path.basename(str(rec.path)), "rows": len(rec), "mode": model.mode,
        "method": METHOD, "degree": model.degree,
        "positions_per_step": None,
        "temperature_source": model.temperature_source,
        "temperature_conditioning": model.temperature_conditioning,
        "valid_c": list(model.valid_c) if model.valid_c else None,
        "g_local": model.g_local,
        **norm_rmse_mg(raw_g, cal, model.g_local),
        "identifiable": {n: bool(v) for n, v in
                         zip(sfem.PARAM_NAMES, model.identifiable, strict=True)},
        "segmentation": {"source": seg.source, "plateaus": len(seg.plateau_ids),
                         "plateau_rows": int(np.sum(seg.step >= 0)),
                         "continuous_rows": seg.continuous_rows},
        "plateaus": [_plateau_row(s, seg, row_c, raw_g, cal, resid, orient, model.g_local)
                     for s in seg.plateau_ids],
        "degree_heldout_rms_ug": {str(d): _r(s, 3) for d, s in scores.items()},
        "chi2_red": _r(solution.chi2_red, 3),
        "rate_gain_ug_per_c_per_min": None if solution.rate_gain_ug is None else {
            "value": [_r(v, 2) for v in solution.rate_gain_ug],
            "stderr": [_r(v, 2) for v in solution.rate_gain_se_ug]},
        "hysteresis_ug": None if solution.hysteresis_ug is None else {
            "value": [_r(v, 2) for v in solution.hysteresis_ug],
            "stderr": [_r(v, 2) for v in solution.hysteresis_se_ug]},
        "bands": bands,
        "identified": identified(model, bands, solution, fit_rate, legs),
        "notes": list(notes),
        "steps": [],
    }


def norm_rmse_mg(raw_g: np.ndarray, cal_g: np.ndarray, g_local: float) -> dict[str, Any]:
    """``rmse_before_mg`` and ``rmse_after_mg``: Eq. 9's |g| RMSE of every fitted row, raw
    and compensated (the figures a step fit gives as the rms over its steps)."""
    return {"rmse_before_mg": _r(norm_rmse_ug(raw_g, g_local) / 1e3),
            "rmse_after_mg": _r(norm_rmse_ug(cal_g, g_local) / 1e3)}


def temperature_bands(row_c: np.ndarray, raw_g: np.ndarray, cal_g: np.ndarray,
                      g_local: float, orient: np.ndarray
                      ) -> list[tuple[np.ndarray, dict[str, Any]]]:
    """Table 6 for data with no steps: per :data:`BAND_C` °C band of ``row_c`` that has
    rows, its row mask and ``band_c``, ``rows``, distinct ``positions`` and Eq. 9's |g|
    RMSE before (``raw_g``) and after (``cal_g``) calibration, mg."""
    edges = np.arange(math.floor(row_c.min() / BAND_C) * BAND_C, row_c.max() + BAND_C, BAND_C)
    out = []
    for lo in edges[:-1]:
        m = (row_c >= lo) & (row_c < lo + BAND_C)
        if m.any():
            out.append((m, {
                "band_c": [float(lo), float(lo + BAND_C)], "rows": int(m.sum()),
                "positions": int(np.unique(orient[m]).size),
                "rmse_before_mg": _r(norm_rmse_ug(raw_g[m], g_local) / 1e3),
                "rmse_after_mg": _r(norm_rmse_ug(cal_g[m], g_local) / 1e3)}))
    return out


def _plateau_row(step: int, seg: Segmentation, row_c: np.ndarray, raw_g: np.ndarray,
                 cal: np.ndarray, resid: np.ndarray, orient: np.ndarray,
                 g_local: float) -> dict[str, Any]:
    """A plateau of a mixed recording as a Table 6 row (its rows fitted with all the others)."""
    m = seg.step == step
    return {"step": int(step), "temperature_c": _r(float(np.mean(row_c[m])), 3),
            "rows": int(m.sum()), "positions": int(np.unique(orient[m]).size),
            "rmse_before_mg": _r(norm_rmse_ug(raw_g[m], g_local) / 1e3),
            "rmse_after_mg": _r(norm_rmse_ug(cal[m], g_local) / 1e3),
            "rmse_vector_after_mg": None if resid.shape[1] == 1 else
            _r(float(np.sqrt(np.mean(resid[m] ** 2))) * 1e3)}


def _legs_agreement(resid: np.ndarray, m: np.ndarray, legs: np.ndarray) -> dict[str, Any] | None:
    """Mean fit residual (µg per axis, or |g| in norm mode) on the heating and cooling legs of
    a band, ± standard error, and whether their difference is within AGREE_SIGMAS."""
    up, down = m & (legs > 0), m & (legs < 0)
    if up.sum() < 3 or down.sum() < 3:
        return None

    def mean_se(sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = resid[sel] * 1e6
        return r.mean(axis=0), r.std(axis=0, ddof=1) / np.sqrt(sel.sum())

    mu, su = mean_se(up)
    md, sd = mean_se(down)
    diff, se = mu - md, np.sqrt(su**2 + sd**2)
    return {
        "up_mean_ug": [_r(v, 2) for v in mu], "up_se_ug": [_r(v, 2) for v in su],
        "down_mean_ug": [_r(v, 2) for v in md], "down_se_ug": [_r(v, 2) for v in sd],
        "difference_ug": [_r(v, 2) for v in diff], "difference_se_ug": [_r(v, 2) for v in se],
        "agree": bool(np.all(np.abs(diff) <= AGREE_SIGMAS * se)),
    }


def identified(model: ThermalModel, bands: list[dict[str, Any]], solution: Any,
               fit_rate: bool, legs: np.ndarray) -> dict[str, list[str]]:
    """What the ramp determined and what it could not, in sentences."""
    yes = [f"{int(model.identifiable.sum())} of 12 SFEM parameters as degree-{model.degree} "
           f"polynomials of the die temperature over {model.valid_c[0]:.1f} .. "  # type: ignore[index]
           f"{model.valid_c[1]:.1f} °C (degree chosen by held-out error)"]  # type: ignore[index]
    no: list[str] = []
    if model.mode == "norm":
        no.append("misalignment M (mx, my, mz): |g| alone does not see a rotation (Eq. 3)")
    if fit_rate and solution.rate_gain_ug is not None:
        k = ", ".join(f"{v:.1f} ± {s:.1f}" for v, s in
                      zip(solution.rate_gain_ug, solution.rate_gain_se_ug, strict=True))
        h = ", ".join(f"{v:.1f} ± {s:.1f}" for v, s in
                      zip(solution.hysteresis_ug, solution.hysteresis_se_ug, strict=True))
        yes.append(f"rate sensitivity k (x, y, z) = {k} µg per °C/min and hysteresis "
                   f"±h = {h} µg (by the die's last excursion) from the heating and cooling "
                   f"legs; the model is the sensor at rest, halfway between the legs (neither "
                   f"term applied by compensate). At one ramp rate ±h and k·rate differ only "
                   f"where the die's rate changes (ends, holds): their σ says how well they "
                   f"were told apart")
    elif not fit_rate and solution.rate_gain_ug is None:
        signs = sorted({int(s) for s in np.unique(legs) if s != 0})
        if len(signs) < 2:
            no.append("rate sensitivity and hysteresis: the die moved one way only, so "
                      "k·dT/dt cannot be told from the bias; it is inside the bias "
                      "polynomial (ramp up and down, or give --rate-gain-ug-per-c-per-min)")
        elif model.provenance.get("rate_gain_ug_per_c_per_min") is None:
            # both ways, but a leg too short to tell k from the bias: say so, not nothing
            rows = {s: int(np.sum(legs == s)) for s in (1, -1)}
            short = ", ".join(f"{'heating' if s > 0 else 'cooling'} {n} row(s)"
                              for s, n in rows.items() if n < MIN_LEG_ROWS)
            no.append(f"rate sensitivity and hysteresis: a leg is too short to fit them "
                      f"({short}; {MIN_LEG_ROWS} needed each way), so k·dT/dt cannot be told "
                      f"from the bias; it is inside the bias polynomial (a longer leg each "
                      f"way, or give --rate-gain-ug-per-c-per-min)")
    thin = [b for b in bands if not b["determined_here"]]
    if thin:
        no.append("bands with too few orientations to determine the model on their own "
                  "(their parameters come from the polynomial through the neighbours): "
                  + ", ".join(f"{b['band_c'][0]:g}..{b['band_c'][1]:g} °C "
                              f"({b['positions']} positions)" for b in thin))
    disagree = [b for b in bands if b["legs"] is not None and not b["legs"]["agree"]]
    both = [b for b in bands if b["legs"] is not None]
    if both:
        (no if disagree else yes).append(
            f"heating and cooling legs agree within {AGREE_SIGMAS:g} standard errors in "
            f"{len(both) - len(disagree)} of {len(both)} band(s) crossed both ways"
            + ("; they disagree in " + ", ".join(f"{b['band_c'][0]:g}..{b['band_c'][1]:g} °C"
                                                  for b in disagree)
               + ": a direction- or rate-dependent error the model does not hold"
               if disagree else ""))
    return {"identified": yes, "not_identified": no}


def format_ramp_report(fit: ThermalFit) -> str:
    """Text: header, the band table (Table 6 for a ramp), identified / not identified."""
    r, m = fit.report, fit.model
    seg = r["segmentation"]
    lines = [
        f"soakcal calibration of {r['recording']} ({r['rows']} rows), continuous temperature "
        f"(ramp): {seg['continuous_rows']} continuous rows, {seg['plateaus']} plateau(s)",
        f"mode: {m.mode} ({int(m.identifiable.sum())} of 12 SFEM parameters identifiable), "
        f"method: {METHOD}, polynomial degree {m.degree} (held-out rms residual by degree: "
        + ", ".join(f"{d}: {s:.2f} µg" for d, s in r["degree_heldout_rms_ug"].items())
        + f"), reduced chi2 {r['chi2_red']}",
        f"temperature: {m.temperature_conditioning}",
        f"valid range: {m.valid_c[0]:.2f} .. {m.valid_c[1]:.2f} °C",  # type: ignore[index]
    ]
    lines += [f"note: {n}" for n in fit.notes]
    lines.append("")
    vec = m.mode == "reference"
    head = ["Band (°C)", "Rows", "Pos", "Before RMSE", "After RMSE"] + \
        (["Vector after"] if vec else []) + ["Up − down residual ± σ (µg)"]
    lines.append("  ".join(h.rjust(w) for h, w in zip(head, _WIDTHS, strict=False)))
    for b in r["bands"]:
        legs = b["legs"]
        leg_txt = "one leg only" if legs is None else " / ".join(
            f"{d:+.1f}±{s:.1f}" for d, s in zip(legs["difference_ug"],
                                                 legs["difference_se_ug"], strict=True)) \
            + ("" if legs["agree"] else "  disagree")
        cells = [f"{b['band_c'][0]:g}..{b['band_c'][1]:g}", str(b["rows"]), str(b["positions"]),
                 f"{b['rmse_before_mg']:.3f} mg", f"{b['rmse_after_mg']:.4f} mg"]
        if vec:
            cells.append(f"{b['rmse_vector_after_mg']:.4f} mg")
        cells.append(leg_txt)
        lines.append("  ".join(c.rjust(w) for c, w in zip(cells, _WIDTHS, strict=False)))
    if r["plateaus"]:
        lines += ["", "plateaus (steps of the recording; fitted with every other row):"]
        for p in r["plateaus"]:
            vec = "" if p["rmse_vector_after_mg"] is None else \
                f", vector after {p['rmse_vector_after_mg']:.4f} mg"
            lines.append(f"  step {p['step']}: {p['temperature_c']:.2f} °C, {p['rows']} rows, "
                         f"{p['positions']} positions, |g| RMSE before "
                         f"{p['rmse_before_mg']:.3f} mg, after {p['rmse_after_mg']:.4f} mg{vec}")
    ident = r["identified"]
    lines.append("")
    lines += [f"identified: {s}" for s in ident["identified"]]
    lines += [f"not identified: {s}" for s in ident["not_identified"]]
    return "\n".join(lines)


_WIDTHS = (10, 5, 4, 11, 11, 12, 28)


def _r(v: float | None, nd: int = 4) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)
