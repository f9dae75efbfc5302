"""Effects the base absorbs that would leave a not-identifiable finding's structure too.

An effect whose pattern the base model absorbs beyond its ``absorbed_max`` (a drift on a
one-way staircase, a rectified vibration that is a per-plateau offset on five plateaus) is
not tested: it is listed "not identifiable here" (the base model absorbs N % of it). Its
remnant after the base is still a direction in the residual, and an effect of that kind,
large enough, leaves structure exactly there. When a ``not_identifiable`` finding's
structure lies in that remnant, the finding's candidates must name the effect too, else
the list of what explains the structure alike leaves out a cause the data cannot exclude
(issue 22: the third generator's rectified vibration on five plateaus was reported as "a
change confined to step 2 or session_offset" beside "vibration_rectification: absorbed
99.2 %").

The finding's structure is the base residual's projection on the columns it was found
with (its term's, or the one-plateau candidate's that the family test chose), off the
base. An absorbed effect joins the candidates where its remnant, at its best grid value,
carries at least :data:`SHARE_ALIKE` of that structure's norm² *and* leaves less of it than
the naming margin (:data:`by_fit.MARGIN` noise variances): the two fit it alike as
``by_fit`` judges candidates that were tested. The share too, because an untested effect
was not significant on its own as by_fit's rivals are: on a weak structure (a glitch of
one reading, ten noise variances) the margin alone let a drift's remnant that carries 40 %
of it in. A finding of single readings (``rows``: an outlier or a glitch of the channel)
is left as it is: a smooth effect's remnant reaches one reading only through that reading's
own recorded temperature (a drift in time against a cubic in a glitched T: 99.9 % of the
reading's structure at 6·10⁻⁵ of the drift kept), which is the glitch candidate's
explanation already.
Nothing is modelled or named by it; the explanation says how much larger than the
structure such an effect would have to be (1/√(1 − absorbed)).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.by_fit import MARGIN
from calibration.discrepancy.effects import BY_ID

ABSORBED_WHY = "the base model absorbs"
# Share of the finding's structure (norm², whitened, off the base) the remnant must carry.
SHARE_ALIKE = 0.9


def extend(pb: Any, findings: list, columns_of: Callable[[Any], np.ndarray | None],
           not_ident: dict[str, dict[str, Any]], lifted: Callable[[Any, float], np.ndarray],
           base: Callable[[], tuple[Any, np.ndarray]]) -> list:
    """``findings`` with each ``not_identifiable`` one's candidates extended by the absorbed
    effects (``not_ident`` entries "the base model absorbs …") that would leave its
    structure (module docstring). ``columns_of(f)``: the finding's raw lifted columns (m, k)
    or None; ``lifted(eff, theta)``: an effect's; ``base()``: the base's orthonormal basis
    and whitened data (``diagnose._basis(pb, [])``), built only when a finding is judged —
    not on every diagnosis."""
    absorbed = [e for e, v in not_ident.items()
                if str(v.get("why", "")).startswith(ABSORBED_WHY)
                and e in BY_ID and not BY_ID[e].per_reading]
    if not absorbed or not any(_judged(f) for f in findings):
        return findings
    U0, yw = base()
    e0 = yw - U0 @ (U0.T @ yw)
    dof = np.sqrt(pb.m / max(pb.m - U0.shape[1], 1))
    noise2 = float(stats.robust_scale(e0[:, None], dof)[0]) ** 2  # the stages' noise scale
    out = []
    for f in findings:
        cands = list(f.where.get("candidates") or [])
        X = columns_of(f) if _judged(f) else None
        if X is None or X.shape[1] == 0:
            out.append(f)
            continue
        s = _structure(pb, U0, e0, X)
        ss = float(s @ s)
        alike = [] if ss <= 0 else [
            (e, share, kept) for e in absorbed if e not in cands
            for share, kept in [_share(pb, U0, s, ss, e, lifted)]
            if share >= SHARE_ALIKE and ss * (1.0 - share) < MARGIN * noise2]
        out.append(f if not alike else _with(f, cands, alike))
    return out


def _judged(f: Any) -> bool:
    """A finding this step looks at: ``not_identifiable`` with candidates, not of single
    readings (module docstring)."""
    return f.effect == "not_identifiable" and bool(f.where.get("candidates")) and not f.rows


def _structure(pb: Any, U0: Any, e0: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The base residual's part along the finding's columns, off the base (whitened)."""
    Q = stats.orthonormal_basis(stats.project_out(U0, pb.whiten(X)))
    return Q @ (Q.T @ e0) if Q.shape[1] else np.zeros_like(e0)


def _share(pb: Any, U0: Any, s: np.ndarray, ss: float, effect_id: str,
           lifted: Callable[[Any, float], np.ndarray]) -> tuple[float, float]:
    """(largest share of ``s`` the effect's remnant carries over its grid, the share of the
    effect's own norm² the base leaves at that grid value)."""
    eff = BY_ID[effect_id]
    best = (0.0, 0.0)
    for theta in eff.grid(pb.ctx):
        Xw = pb.whiten(lifted(eff, theta))
        total = float(np.sum(Xw ** 2))
        if Xw.shape[1] == 0 or total <= 0:
            continue
        R = stats.project_out(U0, Xw)
        kept = float(np.sum(R ** 2)) / total
        if kept <= 0:
            continue
        Q = stats.orthonormal_basis(R)
        share = float(np.sum((Q.T @ s) ** 2)) / ss
        if share > best[0]:
            best = (share, kept)
    return best


def _with(f: Any, cands: Sequence[str], alike: list[tuple[str, float, float]]) -> Any:
    """The finding with the absorbed effects among its candidates and the reason said."""
    said = "; ".join(
        f"{e} ({100 * share:.0f} % of it; the base model absorbs {100 * (1 - kept):.1f} % "
        f"of {e} here, so only an effect of that kind about {1 / np.sqrt(kept):.0f}× this "
        f"structure's size would leave it)" for e, share, kept in alike)
    text = (f"{f.explanation} An effect this protocol's base model absorbs and does not test "
            f"would leave this structure too: {said}.")
    where = {**f.where, "candidates": list(cands) + [e for e, _, _ in alike]}
    return replace(f, where=where, explanation=text)
