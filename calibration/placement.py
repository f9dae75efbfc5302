"""How well a recording's reference directions are known: the ``ref_tol_deg`` column.

A turntable sets each orientation to arc-seconds; a sensor put on a cube face or a
tilt fixture by hand sits a degree or so off the labelled direction. A recording
says its references are hand-placed with the optional column ``ref_tol_deg``: the
one-sigma angle (degrees, > 0) by which the true direction of gravity may differ
from ``ref_*`` at that row. Absent column: the references are exact (the seed's
turntable case). The column must then be filled on every row with a reference;
``soakcal import --format ferraris`` writes it (:data:`HAND_HELD_TOL_DEG`).

The fit uses it as a per-position orientation prior (:func:`calibration.fit.fit_reference`
with ``ref_tol_rad``): |g| keeps its full weight, the direction only decides what
|g| cannot see. docs/fit-honesty.md describes the contract and the evidence.
"""

from __future__ import annotations

import math

import numpy as np

from calibration.errors import RecordingError
from calibration.recording import Recording

REF_TOL_COLUMN = "ref_tol_deg"
# A box held against a table edge or a printed cube face: placement within ~1-2°.
# The fit's result hardly depends on the value as long as it is far above σ/g
# (docs/fit-honesty.md: 0.1° … 5° give the same |g| errors on imucal-ferraris).
HAND_HELD_TOL_DEG = 2.0


def reference_tolerance_rad(rec: Recording) -> np.ndarray | None:
    """Per-row orientation uncertainty (rad) from ``ref_tol_deg``, or None if exact.

    Raises :class:`RecordingError` (file, line, column) for a cell that is not a
    positive number, or an empty cell while others are filled.
    """
    values = _column(rec)
    if values is None:
        return None
    filled = np.isfinite(values)
    if not filled.any():
        return None
    bad = np.flatnonzero(~filled | (values <= 0) | (values >= 90))
    if bad.size:
        i = int(bad[0])
        what = "empty" if not filled[i] else f"{values[i]:g}"
        raise RecordingError(
            rec.path, i + 2, REF_TOL_COLUMN,
            f"{what}: the placement uncertainty must be a number of degrees in (0, 90) on "
            "every row once the column is used")
    return np.radians(values)


def _column(rec: Recording) -> np.ndarray | None:
    """The column as floats (NaN = empty) from parsed columns or the raw cells."""
    if REF_TOL_COLUMN in rec.columns:
        return np.asarray(rec.columns[REF_TOL_COLUMN], float)
    if rec.cells is None or REF_TOL_COLUMN not in rec.header:
        return None
    j = rec.header.index(REF_TOL_COLUMN)
    out = np.full(len(rec.cells), math.nan)
    for i, row in enumerate(rec.cells):
        cell = row[j].strip() if j < len(row) else ""
        if not cell:
            continue
        try:
            out[i] = float(cell)
        except ValueError:
            raise RecordingError(rec.path, i + 2, REF_TOL_COLUMN,
                                 f"{cell!r} is not a number of degrees") from None
        if not math.isfinite(out[i]):
            raise RecordingError(rec.path, i + 2, REF_TOL_COLUMN,
                                 f"{cell!r} is not a finite number of degrees")
    return out
