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
    # The campaign's measured temperature_rate gain (runner: rate_gain.py), when it has one.
    k = provenance.get("rate_gain_ug_per_c_per_min")
    fit = fit_campaign(rec, rate_gain_ug_per_c_per_min=None if k is None
                       else np.asarray(k, float))
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


def rmse_after_ug(fit: Any) -> float:
    """Campaign RMSE after the thermal model (Eq. 9): rms over steps of the per-step values."""
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
