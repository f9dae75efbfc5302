"""The fitting phase: stored measurements → the calibration core → a typed Calibration row.

The only place the engine touches ``calibration/``: a recording built from the
measurement columns, the one fit entry (:func:`calibration.fitting.fit`, the same
gate and fit as ``soakcal calibrate``), and the model document. Kept to one small
function so tests can swap in a fake core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from calibration.fitting import CalibrationFit


@dataclass(frozen=True)
class CalibrationRow:
    """A Calibration row's stored fields (not yet stored) and the fit behind them.

    ``fit`` is the core's :class:`calibration.fitting.CalibrationFit` (the demo prints
    its report, the web page refits figures from it); None from a stand-in core.
    """

    valid_lo_c: float
    valid_hi_c: float
    rmse_ug: float
    model_version: str
    model: dict[str, Any]
    report: dict[str, Any]
    provenance: dict[str, Any]
    fit: CalibrationFit | None = None

    def columns(self) -> dict[str, Any]:
        """The stored columns of the ``calibrations`` table."""
        return {"valid_lo_c": self.valid_lo_c, "valid_hi_c": self.valid_hi_c,
                "rmse_ug": self.rmse_ug, "model_version": self.model_version,
                "model": self.model, "report": self.report, "provenance": self.provenance}


def calibrate_columns(
    columns: dict[str, list[float]], provenance: dict[str, Any]
) -> CalibrationRow:
    """Fit the campaign's measurements as ``soakcal calibrate`` fits its recording.

    The columns carry ``step`` and the held ``setpoint_c`` of each soak, so the gate
    takes the campaign's soaks as steps (calibration/plateaus.py: a declared soak at a
    held setpoint is a step while its die follows the step's line in time).
    ``provenance["rate_gain_ug_per_c_per_min"]`` (x, y, z), when present, is the
    sensor's measured rate gain: the fit subtracts k·dT/dt from the rows first; it
    stays in the model's provenance.
    """
    from calibration.fitting import FitOptions, fit
    from calibration.recording import Recording

    rec = Recording.from_columns({k: np.asarray(v, float) for k, v in columns.items()},
                                 path=provenance.get("recording", "<campaign>"))
    # The campaign's measured temperature_rate gain (runner: rate_gain.py), when it has one.
    k = provenance.get("rate_gain_ug_per_c_per_min")
    result = fit(rec, FitOptions(
        rate_gain_ug_per_c_per_min=None if k is None else tuple(float(v) for v in k)))
    valid = result.valid_c or (math.nan, math.nan)
    model_doc = model_document(result.model)
    model_doc.setdefault("provenance", {}).update(provenance)
    return CalibrationRow(
        valid_lo_c=float(valid[0]), valid_hi_c=float(valid[1]),
        rmse_ug=float(result.rmse_ug), model_version=str(result.model.model_version),
        model=model_doc, report=_jsonable(result.report), provenance=provenance,
        fit=result)


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
