"""A name whose structure decays within each plateau, against a settling after each
plateau's start (issue 22, outside-catalogue effects).

``temperature_rate`` (output ∝ dT/dt) and ``thermal_lag`` (output ∝ ∂f/∂T × the lag's
temperature error) both leave, after the base model, a remnant that fades as the die settles
on each plateau. Anything else that fades after a plateau starts leaves the same remnant:

* a fixture or mount that relaxes after the table's moves (the positions are visited in
  the same order on every plateau, so each plateau starts with the same moves);
* a warm-up of the rig, a heater or fan that settles after each setpoint change.

What the two catalogue effects have that such a settling has not: their size and sign
follow the die's own rate on each plateau — a larger step settles with a larger rate, a
cooling step with the opposite sign, a plateau reached by a small step hardly at all. So a
name of this family is kept only when its fit beats the best *common* settling — per axis,
``exp(−(t − t_start)/τ)`` with ``t_start`` each plateau's first reading and one amplitude
for all plateaus, τ profiled over :data:`TAUS_S` — by :data:`by_fit.MARGIN` noise
variances after 2 per column (AIC, as ``temperature_jump``). Otherwise the term stays in
the model (either removes the structure) and the finding is ``not_identifiable`` with the
name and the settling as candidates, and the experiment that tells them apart.

A staircase of equal steps one way gives every plateau the same rate curve: there the two
are the same regressor and the finding says so. Steps of different sizes or both signs
(up-down, sparse or irregular orders) separate them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.base import per_axis
from calibration.discrepancy.temperature_jump import (
    fits_as_well,
    lead_over_rivals,
    rival_fits_as_well,
    withheld,
)

# The effects whose remnant after the base model fades within each plateau as the die
# settles: their structure is judged against a common settling after each plateau's start.
SETTLING_FAMILY = ("temperature_rate", "thermal_lag")
# Time constants of the rival: from a fixture's relaxation (tens of seconds) to a rig's
# warm-up (an hour, nearly a straight line over a plateau).
TAUS_S = tuple(float(t) for t in np.geomspace(20.0, 3600.0, 16))
MIN_STEPS = 2  # one plateau: its settling is any decay in time (no common shape to test)
EXPERIMENT = ("steps of different sizes and both signs (an up-down or irregular order), so "
              "that the die's rate differs between plateaus while a settling after each "
              "plateau's start does not; or the positions in a different order on each "
              "plateau")


def since_plateau_start_s(ctx: Any) -> np.ndarray:
    """(N,) time since the first reading of each reading's plateau, s."""
    out = np.zeros(ctx.n)
    for s in ctx.step_ids:
        m = ctx.steps == s
        out[m] = ctx.t_s[m] - ctx.t_s[m].min()
    return out


def settling_alike(pb: Any, terms: list, f: Any, alpha: float,
                   not_ident: dict[str, dict[str, str]], notes: list[str],
                   design: Callable[..., tuple[np.ndarray, np.ndarray]]) -> Any:
    """``f`` as found, or ``not_identifiable`` when a settling after each plateau's start,
    the same on every plateau, fits its structure as well (module docstring). ``terms``
    the accepted terms, ``design(pb, terms)`` the whitened design and data."""
    if f.effect not in SETTLING_FAMILY or not f.named_as_modelled or f.rows:
        return f
    ctx = pb.ctx
    term = next((t for t in terms if t.effect_id == f.term_effect and not t.rows), None)
    if term is None or len(ctx.step_ids) < MIN_STEPS:
        return f
    since = since_plateau_start_s(ctx)
    cols = {tau: per_axis(ctx, np.exp(-since / tau)) for tau in TAUS_S}
    found = lead_over_rivals(pb, terms, term, BY_ID[f.effect].one_sided, cols, design)
    if found is None:
        notes.append(f"{f.effect}: not checked against a settling after each plateau's "
                     "start: the recording is too long for that design")
        return f
    lead, tau = found
    if not rival_fits_as_well(lead):
        return f
    settle = (f"a settling after each plateau's start, the same on every plateau (τ ≈ "
              f"{tau:.0f} s: a fixture relaxing after the moves, a warm-up of the rig; "
              "outside the catalogue)")
    why = (f"a per-axis decay exp(−t/{tau:.0f} s) from each plateau's first reading, one "
           f"amplitude for all plateaus, {fits_as_well(f.effect, lead)}: the die's rate "
           "differs too little between the plateaus to tell them")
    return withheld(f, settle, why, EXPERIMENT, not_ident, settling_tau_s=tau)
