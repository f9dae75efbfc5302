"""A thermal/time-family name the data cannot tell from a jump of the output at a
temperature (issue 22, outside-catalogue effects).

The base model follows the temperature with a cubic; a bias that jumps where the die
crosses a temperature T* (a package or solder phase change, a relay or heater that switches
at a threshold) is outside it and outside the catalogue. Whatever else changes between the
plateaus on the two sides of T* makes the same per-plateau offset:

* a power cycle at plateau k on a staircase that never comes back (``session_offset``
  without a session column: the plateaus from k on are the hot, or the cold, ones);
* the vibration power recorded in ``sd_*`` when the compressor runs on the cold plateaus
  only (``vibration_rectification``);
* a direction of the last excursion that happens to split the plateaus by temperature
  (``thermal_hysteresis`` on a random order), frost that forms on the cold plateaus.

A vibration step is no exception: the compressor's duty follows the temperature
(docs/effects.md), so its step and a jump at a temperature coincide by design, not by
chance. A power cycle logged in a ``session`` column is (``CatalogueEffect.cause_recorded``):
the operator's act has nothing to do with the temperature.

So a name of the family whose per-axis offsets are all per plateau or per history
(``CatalogueEffect.named_by_fit``) is kept only when its fit beats the best such jump
(per-axis offset of the plateaus whose median temperature is above T*, T* profiled over
the midpoints between the plateaus' temperatures) by :data:`by_fit.MARGIN` noise variances,
each fit less 2 per column (AIC). Otherwise the term stays in the model (either removes
the structure) and the finding is ``not_identifiable`` with the name and "a jump of the
output where the temperature crosses T*" as candidates, and the experiment that tells
them apart. A term with structure the jump does not have (a session jump on an up-down
campaign, where both legs cross T*; vibration that also changes on warm plateaus; a lag
that decays within each plateau) out-fits it and keeps its name.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.by_fit import MARGIN
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.base import per_axis

EXPERIMENT = ("repeat a temperature on both sides of the change in time (an up-down or "
              "repeated staircase): a jump at a temperature re-occurs at every crossing, in "
              "both directions")
MIN_GAP_C = 0.5  # plateaus closer than this in temperature are one temperature


def thresholds_c(step_temp_c: dict[int, float]) -> list[float]:
    """Midpoints between the distinct plateau temperatures (sorted)."""
    t = np.sort(np.asarray(list(step_temp_c.values()), float))
    levels = [t[0]] if t.size else []
    for x in t[1:]:
        if x - levels[-1] > MIN_GAP_C:
            levels.append(x)
    return [float((a + b) / 2.0) for a, b in zip(levels[:-1], levels[1:], strict=True)]


def jump_column(ctx: Any, threshold_c: float) -> np.ndarray:
    """(N,) 1 on readings of a plateau whose median temperature is above ``threshold_c``."""
    hot = {s for s, t in ctx.step_temp_c.items() if t > threshold_c}
    return np.isin(ctx.steps, sorted(hot)).astype(float)


def temperature_jump_alike(pb: Any, terms: list, f: Any, alpha: float,
                           not_ident: dict[str, dict[str, str]], notes: list[str],
                           design: Callable[..., tuple[np.ndarray, np.ndarray]]) -> Any:
    """``f`` as found, or ``not_identifiable`` when a jump at a temperature fits its
    structure as well (module docstring). ``terms`` the accepted terms, ``design(pb, terms)``
    the whitened design and data."""
    eff = BY_ID.get(f.effect)
    if eff is None or not f.named_as_modelled or f.rows or not eff.named_by_fit:
        return f
    if eff.cause_recorded(pb.ctx):  # a logged power cycle at the jump is the operator's act
        return f
    term = next((t for t in terms if t.effect_id == f.term_effect and not t.rows), None)
    ctx = pb.ctx
    grid = thresholds_c(ctx.step_temp_c)
    if term is None or not grid:
        return f
    cols = {t_c: per_axis(ctx, jump_column(ctx, t_c)) for t_c in grid}
    found = lead_over_rivals(pb, terms, term, eff.one_sided, cols, design)
    if found is None:
        notes.append(f"{f.effect}: not checked against a jump of the output at a "
                     "temperature: the recording is too long for that design")
        return f
    lead, t_best = found
    if not rival_fits_as_well(lead):
        return f
    below = sorted(s for s, t in ctx.step_temp_c.items() if t < t_best)
    above = sorted(s for s, t in ctx.step_temp_c.items() if t > t_best)
    jump = (f"a jump of the output where the temperature crosses ≈ {t_best:.1f} °C (a "
            "package or solder change at a temperature; outside the catalogue)")
    why = (f"a per-axis jump of the plateaus above {t_best:.1f} °C (steps {above}) against "
           f"those below (steps {below}) {fits_as_well(f.effect, lead)}: the recording "
           "holds too little of what the term does beyond that jump")
    return withheld(f, jump, why, EXPERIMENT, not_ident, jump_at_c=t_best)


def rival_fits_as_well(lead: float) -> bool:
    """The named term leads a rival outside the catalogue by less than by_fit's
    :data:`MARGIN` noise variances (:func:`lead_over_rivals`): the name is withheld."""
    return bool(np.isfinite(lead) and lead < MARGIN)


def fits_as_well(effect: str, lead: float) -> str:
    """The clause that says so, for the reason of :func:`withheld`."""
    return (f"fits the structure as well (the {effect} term leads it by {lead:.1f} noise "
            f"variances after 2 per column, under {MARGIN:.3g})")


def withheld(f: Any, rival: str, why: str, experiment: str, not_ident: dict[str, dict],
             **where: Any) -> Any:
    """Finding ``f`` as ``not_identifiable`` between its name and ``rival`` (a phrase),
    ``why`` they fit alike and ``experiment`` that separates them; its name is listed in
    ``not_ident`` with the same reason. ``where`` adds to the finding's location."""
    not_ident.setdefault(f.effect, {"effect": f.effect, "why": f"not separable from "
                                    f"{rival}: {why}", "experiment": experiment})
    how = "; ".join(x for x in (BY_ID[f.effect].experiment, experiment) if x)
    return replace(
        f, effect="not_identifiable",
        where={**f.where, "candidates": [f.effect, rival], **where},
        explanation=(f"Structure beyond noise that {f.effect} or {rival} explain alike: "
                     f"{why}. It is modelled (with the {f.effect} term) but not named; to "
                     f"separate them: {how}."),
        parameters={}, parameter_sd={}, confusers=[])


def lead_over_rivals(pb: Any, terms: list, term: Any, one_sided: bool,
                     rivals: dict[Any, np.ndarray],
                     design: Callable[..., tuple[np.ndarray, np.ndarray]]
                     ) -> tuple[float, Any] | None:
    """How far ``term``'s fit beats the best of ``rivals`` (label → raw (N,3,k) columns),
    in noise variances after 2 per column (AIC), each fitted after the other ``terms``; and
    that rival's label. ``inf`` when a side has no column left; None when the recording is
    too long for the design (the caller says so)."""
    others = [t for t in terms if t is not term]
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in others) + max(
        (c.shape[2] for c in rivals.values()), default=0)
    if 8 * pb.m * p > stats.TALL_BYTES or pb.m <= p + 10:
        return None
    Xw, yw = design(pb, others)
    U = stats.orthonormal_basis(Xw)
    del Xw
    e = yw - U @ (U.T @ yw)
    q_term, k_term = stats.explained_ss(U, pb.whiten(term.X), e, one_sided)
    fits = {lab: stats.explained_ss(U, pb.whiten(pb.lift(c)), e) for lab, c in rivals.items()}
    best, (q_riv, k_riv) = max(fits.items(), key=lambda kv: kv[1][0])
    if k_term == 0 or k_riv == 0:
        return float("inf"), best
    k_max = max(k_term, k_riv)
    s2 = max((float(e @ e) - max(q_term, q_riv)) / max(e.size - U.shape[1] - k_max, 1),
             1e-300)
    return (q_term / s2 - 2.0 * k_term) - (q_riv / s2 - 2.0 * k_riv), best
