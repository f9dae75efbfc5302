"""What a warm-up's report says about the spans a quantised channel's rebuild left unresolved.

Where the die rests or turns round inside one step of a coarse channel
(:class:`calibration.temperature_dequantise.UnresolvedSpan`) its temperature is known
only to the step's band, ±½ LSB. The rebuild puts a value there (the step's value at a
rest, a parabola's guess at a turn); the fit keeps those readings at that value. Leaving
them out was measured on the second generator's 1 °C warm-ups (docs/benchmarks.md, "Rests
and turns inside a 1 °C step") and raised the held-out error on 5 of 10 logs (one from a
win to a loss): a held-out reading inside a rest is compensated at the same rebuilt
value, and the fit that saw the rest maps that value to the rest's bias. So the readings
stay in the fit, and what is not known is said, never silently: the report's
``unresolved_temperature`` lists each span (its times, step, readings and bound) and how
many readings the fit took at the rebuild's value there.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.recording import Recording
from calibration.temperature_dequantise import Dequantised

TREATMENT = ("kept in the fit at the rebuilt value (the step's value at a rest, the "
             "parabola of the neighbouring slopes at a turn): the die temperature there is "
             "known only to the step's band; leaving them out raised the held-out error")


def unresolved_record(captures: Recording, dq: Dequantised | None) -> dict[str, Any] | None:
    """The report's ``unresolved_temperature`` record (None: nothing unresolved)."""
    if dq is None or not dq.unresolved:
        return None
    inside = dq.unresolved_mask(captures.t_s)
    n = captures.columns.get("n")
    return {
        "lsb_c": dq.lsb_c,
        "spans": [s.to_dict() for s in dq.unresolved],
        "readings_inside": int(np.sum(inside)),
        "samples_inside": int(np.sum(n[inside])) if n is not None else int(np.sum(inside)),
        "readings": int(inside.size),
        "treatment": TREATMENT,
    }


def note(record: dict[str, Any]) -> str:
    """The report's line on the readings whose temperature is a guess, and their bound."""
    return (f"{record['readings_inside']} of {record['readings']} capture means "
            f"({record['samples_inside']} samples) lie in {len(record['spans'])} span(s) where "
            f"the die rested or turned inside one {record['lsb_c']:g} °C step: their "
            f"temperature is NOT RESOLVED below the step's band (listed under "
            f"unresolved_temperature); they are {TREATMENT}")
