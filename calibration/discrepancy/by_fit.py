"""Which of several significant confusers the data name: the best fit, by a clear margin.

Forward selection (diagnose.py) ranks candidates by their multiplicity-adjusted p, which
answers "is there structure?" fairly but not "which effect is it?": a profiled effect
(a session jump at an unknown plateau, ~20 grid values) pays a Šidák penalty its rival
(hysteresis, one column per axis) does not, and at p ≈ 10⁻¹⁵ that penalty, not the data,
decided the name (issue 22: a session offset at twice its detectable size was called
thermal hysteresis 5 times in 10 on the second generator).

Among the winner and its declared confusers that explain the same structure (each
significant at α on its own before the term is added), a name is given only when the data
choose it: its explained sum of squares q (whitened, so Δq/2 is a log likelihood ratio),
less 2 per column (AIC) and, for a profiled θ, averaged over θ (the Occam factor), beats
every rival's best q by :data:`MARGIN` noise variances (:func:`name_by_fit`). Otherwise
the data do not tell them apart under this protocol: the best fit stays in the model
(either removes the structure) and the finding is reported as ``not_identifiable`` with
the close candidates — never a confident wrong name. Example: on one up-down cycle with
no session column, hysteresis (the cooling leg offset from the heating leg) and a power
cycle at the turn differ only on the first plateau, which is reached by cooling from
room temperature; at twice the detectable size that plateau rarely decides.

Only pairs whose modules both set ``CatalogueEffect.named_by_fit`` take part (the
thermal/time family: their regressors are all per-axis offsets in time or temperature
history, comparable column for column).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.level import ALPHA

# χ²₁ at 1 − 2α (6.63 at α = 0.5 %): a wrong name no more often than a false alarm. Under
# the rival, with the two effects' separation δ (the noncentrality of the winner's columns
# off the rival's), Δq = q_name − q_rival ~ N(−δ, 4δ), so P(Δq ≥ M) = Φ(−(M + δ)/(2√δ)),
# largest at δ = M: Φ(−√M) = ½ P(χ²₁ > M) = α whatever δ. Why not χ²₁ at 95 % (3.84, as
# before): that bound is 2.5 % per rival, five times the verdict's level, and on the second
# generator a hysteresis at twice its detectable size was named `bias_drift` (Δq 6.0 at
# δ ≈ 10) and `temperature_rate` (Δq 4.1 at δ ≈ 1) at that rate (issue 22).
MARGIN = float(chi2.isf(2.0 * ALPHA, 1))


def _related(a: str, b: str) -> bool:
    ea, eb = BY_ID[a], BY_ID[b]
    return (ea.named_by_fit and eb.named_by_fit
            and (b in ea.confusers or a in eb.confusers))


def rivals(best: stats.CandidateTest, tests: dict[str, stats.CandidateTest],
           alpha: float) -> list[str]:
    """Declared confusers of ``best`` that are significant on their own at this stage."""
    if best.effect_id not in BY_ID:
        return []
    return [k for k, t in tests.items() if k != best.effect_id and _related(best.effect_id, k)
            and not BY_ID[k].per_reading and t.p_adj <= alpha]


def name_by_fit(best: stats.CandidateTest, tests: dict[str, stats.CandidateTest],
                e: np.ndarray, n_model_cols: int,
                explained: Callable[[Any, float], tuple[float, int]],
                alpha: float, ctx: Any = None) -> tuple[stats.CandidateTest, list[str]]:
    """The test to add and, when no candidate is clearly best, the candidates the data
    cannot tell apart (else empty).

    ``e`` the whitened residual of the current model (``n_model_cols`` columns);
    ``explained(effect, θ)`` → (explained SS, columns) of a candidate at θ.

    Each candidate's fit is its explained SS in noise variances less 2 per column (AIC),
    read two ways. ``high``: at its best θ. ``low``: for a profiled θ (a jump's plateau, a
    lag's τ) the likelihood averaged over its grid (the Occam factor of a uniform prior on
    θ), so a jump placed wherever it fits best does not outscore a fixed-shape term by that
    freedom alone (a linear drift was called a session jump, 2 of 18 on the project's
    blind set). A name needs its ``low`` to beat every rival's ``high`` by :data:`MARGIN`:
    whatever the prior on θ, the data chose it. Else the best ``high`` is modelled and the
    candidates within reach of it are reported.

    ``ctx`` (the recording's design): a rival's bar is its best fit over its whole grid, the
    places its test left out as absorbed by the base model included. Why: a step whose
    boundary the cubic absorbs 99.1 % of is not tested there, but the same structure reached
    through a regressor the cubic absorbs less of (a vibration offset that steps at that
    boundary) fits no better than that step, and was named over it (issue 22). A declared
    confuser that is not significant on its tested places, but has such untested places,
    is a bar too (never named from them: its term would be fitted where it was not tested).
    """
    if best.effect_id not in BY_ID or not BY_ID[best.effect_id].named_by_fit:
        return best, []
    group = [best.effect_id] + rivals(best, tests, alpha)
    bars_only = [] if ctx is None else [
        k for k, t in tests.items() if k not in group and _related(best.effect_id, k)
        and not BY_ID[k].per_reading and _untested(BY_ID[k], t, ctx)]
    if len(group) == 1 and not bars_only:
        return best, []
    fits = {g: _profile(BY_ID[g], tests[g], explained) for g in group + bars_only}
    k_max = max(k for _, k in fits.values())
    top_q = max(max(q.values()) for q, _ in fits.values())
    s2 = max((float(e @ e) - top_q) / max(e.size - n_model_cols - k_max, 1), 1e-300)
    high, low, bar = {}, {}, {}
    for g, (q, k) in fits.items():
        z = np.array(list(q.values())) / s2
        high[g] = float(z.max()) - 2.0 * k
        low[g] = high[g] + 2.0 * float(np.log(np.mean(np.exp((z - z.max()) / 2.0))))
        bar[g] = max(high[g], _best_anywhere(BY_ID[g], q, explained, ctx) / s2 - 2.0 * k)
    for g in sorted(group, key=low.get, reverse=True):
        if all(low[g] - bar[h] >= MARGIN for h in group + bars_only if h != g):
            return tests[g], []
    fitted = max(group, key=high.get)
    return tests[fitted], [fitted] + [g for g in group + bars_only
                                      if g != fitted and low[fitted] - bar[g] < MARGIN]


def _profile(eff: Any, test: stats.CandidateTest,
             explained: Callable[[Any, float], tuple[float, int]]
             ) -> tuple[dict[float, float], int]:
    """Explained SS over the candidate's usable θ (its one θ when linear), and its columns."""
    thetas = sorted(test.profile) if len(test.profile) > 1 else [test.theta]
    out, k = {}, 0
    for th in thetas:
        out[th], k = explained(eff, th)
    return out, k


def _untested(eff: Any, test: stats.CandidateTest, ctx: Any) -> bool:
    """Places on ``eff``'s grid its test left out (absorbed by the base model)."""
    return any(np.isfinite(th) and th not in test.profile for th in eff.grid(ctx))


def _best_anywhere(eff: Any, q: dict[float, float],
                   explained: Callable[[Any, float], tuple[float, int]], ctx: Any) -> float:
    """The best explained SS of ``eff`` over its whole grid (``q``: the usable θ's, known)."""
    best = max(q.values())
    if ctx is None:
        return best
    for th in eff.grid(ctx):
        if np.isfinite(th) and th not in q:
            got, k = explained(eff, th)
            if k:
                best = max(best, got)
    return best


def as_not_separable(f: Any, candidates: list[str], not_ident: dict[str, dict[str, str]],
                     why: str = "") -> Any:
    """A finding whose structure ``candidates`` fit alike, reported as not identifiable
    (``why``: the reason, when not the fits' closeness)."""
    why = why or ("they fit this recording alike (explained variance within "
                  f"{MARGIN:.3g} noise variances of each other): the protocol holds too little "
                  "of what tells them apart")
    for c in candidates:
        others = ", ".join(x for x in candidates if x != c)
        not_ident.setdefault(c, {"effect": c, "why": f"not separable from {others} here: "
                                 f"{why}", "experiment": BY_ID[c].experiment})
    how = "; ".join(dict.fromkeys(
        f"{BY_ID[c].experiment}" for c in candidates if BY_ID[c].experiment))
    return replace(
        f, effect="not_identifiable", where={**f.where, "candidates": list(candidates)},
        explanation=(f"Structure beyond noise that {' or '.join(candidates)} explain alike: "
                     f"{why}. It is modelled (with the {f.effect} term) but not named; to "
                     f"separate them: {how}."),
        parameters={}, parameter_sd={}, confusers=[])
