"""The fitting phase: stored measurements → the calibration core → a Calibration row's values.

The only place the engine touches ``calibration/``: a recording built from
the measurement columns, ``fit_campaign``, and the model document. Kept to
one small function so tests can swap in a fake core.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def calibrate_columns(
    columns: dict[str, list[float]], provenance: dict[str, Any]
) -> dict[str, Any]:
    """Fit the thermal SFEM model; return the Calibration row fields (not yet stored).

    Keys: valid_lo_c, valid_hi_c, rmse_ug, model_version, model, report, provenance.
    ``provenance["rate_gain_ug_per_c_per_min"]`` (x, y, z), when present, is the
    sensor's measured rate gain: the fit subtracts k·dT/dt from the rows first
    (``calibration.thermal.fit_campaign``); it stays in the model's provenance.
    """
    from calibration.recording import Recording
    from calibration.thermal import fit_campaign

    rec = Recording.from_columns({k: np.asarray(v, float) for k, v in columns.items()},
                                 path=provenance.get("recording", "<campaign>"))
    ramp = (provenance.get("spec") or {}).get("method") == "ramp"
    # The campaign's measured temperature_rate gain (runner: rate_gain.py), when it has one.
    k = provenance.get("rate_gain_ug_per_c_per_min")
    fit = fit_ramp(rec) if ramp else fit_campaign(
        rec, rate_gain_ug_per_c_per_min=None if k is None else np.asarray(k, float))
    model = fit.model
    valid = model.valid_c or (math.nan, math.nan)
    model_doc = model_document(model)
    model_doc.setdefault("provenance", {}).update(provenance)
    return {
        "valid_lo_c": float(valid[0]),
        "valid_hi_c": float(valid[1]),
        "rmse_ug": rmse_after_ug(fit),
        "model_version": str(model.model_version),
        "model": model_doc,
        "report": _jsonable(fit.report),
        "provenance": provenance,
        "_fit": fit,  # the runner drops this before storing; the demo prints its report
    }


def fit_ramp(rec: Any) -> Any:
    """A ramp campaign's fit, decided as ``soakcal calibrate`` decides (calibration/cli.py):
    its sweeps are steps only where the die stood still (``segment_recording``), the gate
    picks the fit, the continuous fit's model is checked. Raises ``CalibrationError``."""
    from calibration import gate
    from calibration.continuous import fit_continuous
    from calibration.errors import CalibrationError
    from calibration.plateaus import segment_recording
    from calibration.thermal import fit_campaign

    seg = segment_recording(rec)
    decided = gate.plan(rec, continuous=seg.is_continuous)
    if decided.kind == "continuous":
        fit = fit_continuous(rec, seg)
        gate.check_model(fit.model, rec, fit.row_temperature_c)
    elif decided.kind == "sfem":  # every sweep a plateau: the chamber did not move
        fit = fit_campaign(rec)
    else:
        raise CalibrationError(decided.reason)
    fit.notes.insert(0, decided.reason)
    fit.report.setdefault("notes", []).insert(0, decided.reason)
    return fit


def rmse_after_ug(fit: Any) -> float:
    """Campaign RMSE after the thermal model (Eq. 9): rms over steps of the per-step values;
    a continuous fit's (no steps): over its temperature bands' rows."""
    bands = fit.report.get("bands") if not fit.steps else None
    if bands:
        rows = np.array([b["rows"] for b in bands], float)
        mg = np.array([np.nan if b["rmse_after_mg"] is None else b["rmse_after_mg"]
                       for b in bands], float)
        ok = np.isfinite(mg)
        return float(np.sqrt(np.sum(rows[ok] * mg[ok] ** 2) / np.sum(rows[ok])) * 1e3) \
            if ok.any() else math.nan
    vals = [st.rmse_polynomial_ug for st in fit.steps if math.isfinite(st.rmse_polynomial_ug)]
    return float(np.sqrt(np.mean(np.square(vals)))) if vals else math.nan


def model_document(model: Any) -> dict[str, Any]:
    """The model JSON document (the same one ``soakcal calibrate -o`` writes)."""
    from calibration.model_file import dump_model_dict  # the fitting phase's import, on use

    return _jsonable(dump_model_dict(model))


def _jsonable(v: Any) -> Any:
    """NumPy → plain JSON types; NaN/inf → None (PostgreSQL JSON rejects NaN)."""
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, np.bool_ | bool):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, float | np.floating):
        f = float(v)
        return f if math.isfinite(f) else None
    return v
