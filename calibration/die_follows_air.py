"""The die follows the air around it: on a plateau the air holds, the die approaches it.

A chamber's controller holds the air at each setpoint; the sensor's die exchanges heat
with that air through the fixture and follows it with a lag, moving at a rate
proportional to how far behind it is. So through a soak's plateau ``chamber_c`` holds
(within its controller's noise) while ``sensor_c`` may still be approaching, and never the
other way round: air that moves through a plateau while the die holds still would need a
die that no heat reaches.

Swapped columns (the die's temperature written as ``chamber_c``) show exactly that
impossible pattern on every plateau, and nothing else in a recording shows it: both
columns have the same span, units and steps, and a model fitted in the air's temperature
is a model of a lag that the compensation never sees. :func:`die_leads_air` names it when,
on at least :data:`MIN_STEPS` steps, ``chamber_c`` moves (its straight-line change over
the step at least :data:`MOVE_MIN_C` and :data:`MOVE_SIGMAS` standard errors) by more than
:data:`MOVE_RATIO` times ``sensor_c`` does, and on no step does ``sensor_c`` move more than
``chamber_c``. Ramps (both move) and soaks that waited for the die (neither moves) say
nothing, and nothing is refused there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from calibration.recording import Recording

# A channel "moves" through a step when its straight-line change over the step's rows is
# at least this (°C) ...
MOVE_MIN_C = 0.1
# ... and this many standard errors of that change (a controller's ±0.01 °C is not a move).
MOVE_SIGMAS = 10.0
# The air moves this many times more than the die on a swapped step. A die lagging the air
# by τ moves (air − die)/τ; for the air to move ten times more than the die through a
# plateau the die would need a lag of ten plateaus, and it would then be far from every
# setpoint (which the soak's stability decision does not accept).
MOVE_RATIO = 10.0
# Steps that must show it (one plateau can be anything: a door opened, a probe touched).
MIN_STEPS = 3
# Rows a step needs for a straight line with a standard error.
MIN_ROWS_PER_STEP = 4


@dataclass(frozen=True)
class StepMoves:
    """The straight-line change through one step (°C) of each channel and its standard
    error."""

    step: int
    air_c: float
    air_se_c: float
    die_c: float
    die_se_c: float

    def air_moves(self) -> bool:
        return _moves(self.air_c, self.air_se_c)

    def die_moves(self) -> bool:
        return _moves(self.die_c, self.die_se_c)


def _moves(change_c: float, se_c: float) -> bool:
    return abs(change_c) >= MOVE_MIN_C and abs(change_c) >= MOVE_SIGMAS * se_c


def _line_change(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The change of a least-squares line of ``y`` over ``t``'s span, and its standard
    error (from the line's residual)."""
    tc = t - t.mean()
    stt = float(tc @ tc)
    slope = float(tc @ (y - y.mean())) / stt
    resid = y - y.mean() - slope * tc
    se = float(np.sqrt(float(resid @ resid) / max(t.size - 2, 1) / stt))
    span = float(np.ptp(t))
    return slope * span, se * span


def step_moves(rec: Recording) -> list[StepMoves]:
    """Each step's straight-line change of ``chamber_c`` and ``sensor_c``; empty when
    either column or the step column is missing."""
    if not (rec.has("chamber_c") and rec.has("sensor_c") and rec.has("step")):
        return []
    t = np.asarray(rec.t_s, float)
    air = np.asarray(rec.columns["chamber_c"], float)
    die = np.asarray(rec.columns["sensor_c"], float)
    steps = np.asarray(rec.columns["step"], float)
    ok = np.isfinite(t) & np.isfinite(air) & np.isfinite(die) & np.isfinite(steps)
    out = []
    for s in np.unique(steps[ok]):
        idx = np.flatnonzero(ok & (steps == s))
        if idx.size < MIN_ROWS_PER_STEP or np.ptp(t[idx]) <= 0:
            continue
        a, a_se = _line_change(t[idx], air[idx])
        d, d_se = _line_change(t[idx], die[idx])
        out.append(StepMoves(int(s), a, a_se, d, d_se))
    return out


def die_leads_air(rec: Recording, outcome: str = "no model written") -> str | None:
    """Why ``sensor_c`` cannot be the die of this ``chamber_c`` (the air moves through its
    plateaus while the die holds: module docstring), with the fix; or None."""
    moves = step_moves(rec)
    swapped = [m for m in moves
               if m.air_moves() and abs(m.die_c) * MOVE_RATIO < abs(m.air_c)]
    followed = [m for m in moves if m.die_moves() and abs(m.die_c) > abs(m.air_c)]
    if len(swapped) < MIN_STEPS or followed:
        return None
    air = float(np.median([abs(m.air_c) for m in swapped]))
    die = float(np.median([abs(m.die_c) for m in swapped]))
    return (f"chamber_c moves through its plateaus while sensor_c holds (median change "
            f"{air:.2f} °C against {die:.3f} °C, on {len(swapped)} of {len(moves)} steps): "
            f"the air is held by the chamber and the die follows it, never the other way "
            f"round, so the two columns look swapped; {outcome}: write the die's "
            f"temperature as sensor_c and the chamber air's as chamber_c (docs/recording.md)")
