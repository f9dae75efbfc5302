"""A warm-up fitted only where a quantised channel's rebuild resolved the die temperature.

Where the die rests or turns round inside one step of a coarse channel
(:class:`calibration.temperature_dequantise.UnresolvedSpan`) its temperature is known
only to the step's band, ±½ LSB. The rebuild puts a value there (the step's value at a
rest, a parabola's guess at a turn), but that value is invented: a bias of 1 mg/°C read
at it is wrong by up to 0.5 mg, and the error is the *same* for every reading of the span
(one unknown temperature, or one unknown excursion), so a per-reading weight cannot
express it: 100 readings with a common error pull the polynomial as 100 readings do.
Treated properly, the span's temperature is one more unknown, bounded by the band; a
bias polynomial (Eq. 8) with a free temperature for those readings fits them exactly
for any curve whose values over the band cover their bias, so they carry nothing about
the curve's shape beyond that bound. That is the
same as leaving them out, which is what the fit does: every reading inside an
unresolved span is left out of the warm-up fit (the degree test, the rate check and the
coefficients), counted, and said in the report (``unresolved_temperature``) and notes.
``compensate`` still rebuilds and compensates those readings (at the rebuild's value:
the best single guess, its bound stated).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.gate import Orientations
from calibration.recording import Recording
from calibration.temperature_dequantise import Dequantised


def resolved_only(captures: Recording, orientations: Orientations, dq: Dequantised | None
                  ) -> tuple[Recording, Orientations, dict[str, Any] | None]:
    """The captures (and their orientation labels) outside every unresolved span, and the
    report's ``unresolved_temperature`` record (None: nothing unresolved, all kept)."""
    if dq is None or not dq.unresolved:
        return captures, orientations, None
    out = dq.unresolved_mask(captures.t_s)
    keep = ~out
    n = captures.columns.get("n")
    samples = int(np.sum(n[out])) if n is not None else int(np.sum(out))
    record: dict[str, Any] = {
        "lsb_c": dq.lsb_c,
        "spans": [s.to_dict() for s in dq.unresolved],
        "excluded_readings": int(np.sum(out)),
        "excluded_samples": samples,
        "kept_readings": int(np.sum(keep)),
        "treatment": "left out of the fit: the die temperature there is known only to the "
                     "step's band, one unknown shared by all the span's readings",
    }
    return captures.subset(keep), _kept(orientations, keep), record


def note(record: dict[str, Any]) -> str:
    """The report's line on what was left out and why."""
    spans = record["spans"]
    return (f"{record['excluded_readings']} of "
            f"{record['excluded_readings'] + record['kept_readings']} capture means "
            f"({record['excluded_samples']} samples) in {len(spans)} span(s) where the die "
            f"rested or turned inside one {record['lsb_c']:g} °C step were LEFT OUT of the "
            f"fit: their temperature is known only to the step's band (listed under "
            f"unresolved_temperature); the model is fitted on the "
            f"{record['kept_readings']} others")


def _kept(orientations: Orientations, keep: np.ndarray) -> Orientations:
    """The orientations of the kept readings, relabelled (an orientation seen only inside
    the spans is dropped)."""
    labels = orientations.labels[keep]
    present = np.unique(labels)
    relabel = np.full(orientations.count, -1, int)
    relabel[present] = np.arange(present.size)
    return Orientations(labels=relabel[labels], directions=orientations.directions[present],
                        counts=np.bincount(relabel[labels], minlength=present.size),
                        threshold_deg=orientations.threshold_deg)
