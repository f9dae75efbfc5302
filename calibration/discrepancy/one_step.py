"""Structure whose evidence is one plateau: found, not named, still reported (issue 22).

Forward selection (diagnose.py, docs/diagnosis.md §5) adds the best candidate when its
family-wise p is ≤ α/2. ``diagnose._concentrated_on_one_step`` then frees one plateau
(per axis 1, a_x, a_y, a_z on that step); if the candidate is no longer significant, its
evidence is that plateau alone and the name is withheld: a channel step next to the end of
a staircase, a rate term on the plateau reached from the other side, a vibration confined to
the boundary plateau are then as well "this plateau differs" (a warm-up, self-heating, a
re-seat). Withholding the name is right; dropping the structure was not: the family test had
found it at its level, and the verdict came out "consistent" or the scan reported the same
structure as ``unexplained`` without the candidates.

Here each rejection is recorded (:class:`OneStep`) and, at the end, the rejected effects no
other finding covers become one ``not_identifiable`` finding (:func:`report`) whose
candidates are "a change confined to step k" first (what the check itself proposes) and the
rejected effects by p. It re-labels structure the family test already found at α/2, so the
verdict's false-alarm level is unchanged in design: no new test decides a mismatch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.context import AXES
from calibration.discrepancy.effects import BY_ID

TEST = "forward-selection family test; not named: its evidence is one plateau"
# Why these plateaus tell a one-plateau change from an effect: the change is free on one
# plateau only, so an effect is separated by what it predicts on the others.
SEPARATE = ("more plateaus, so that the effect's shape on the other plateaus is seen beside the "
            "one that carries it; temperatures revisited in an up-down or irregular order, so "
            "that a change confined to one plateau does not recur where the effect would; the "
            "plateau repeated after a pause")


@dataclass(frozen=True)
class OneStep:
    """A candidate withheld because a free change of one plateau takes its evidence."""

    effect_id: str
    step: int
    p_family: float
    axes: tuple[str, ...]
    X: np.ndarray  # (m, k) the rejected term's unweighted columns (residual space)


def rejected(pb: Any, effect_id: str, X: np.ndarray, coef: np.ndarray, step: int,
             p_family: float) -> OneStep:
    """The record of one rejection; ``coef`` the term's fitted coefficients (for its axes)."""
    return OneStep(effect_id, int(step), float(p_family), _axes(pb, X @ coef, step), X)


def _axes(pb: Any, contrib_g: np.ndarray, step: int) -> tuple[str, ...]:
    """Axes where the term's fitted contribution on its plateau is ≥ half the largest."""
    if pb.mode != "reference":
        return ("norm",)
    on = pb.ctx.steps[pb.row] == step
    w2 = (contrib_g * pb.w) ** 2
    per = np.array([float(np.sum(w2[on & (pb.axis == a)])) for a in range(3)])
    if per.max() <= 0:
        return tuple(AXES)
    return tuple(AXES[a] for a in range(3) if per[a] >= 0.5 * per.max())


def still_seen(pb: Any, basis: Callable[..., tuple[np.ndarray, np.ndarray]], terms: list,
               alpha: float) -> Callable[[OneStep], bool]:
    """Does a rejected term still explain structure (single F test at α) after the final
    model? Used only where other findings stand: one of them may have taken the structure.
    ``basis(pb, terms)``: the orthonormal basis of the whitened design and the whitened data
    (``diagnose._basis``: held as its recipe on a long recording). The final model's basis
    and residual are built once, on the first record asked about, and shared by the
    others."""
    final: list[tuple[np.ndarray, np.ndarray]] = []

    def seen(rec: OneStep) -> bool:
        if not final:
            U, yw = basis(pb, terms)
            final.append((U, yw - U @ (U.T @ yw)))
        U, e = final[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            lp, _, k, _, _ = stats.linear_stats(U, pb.whiten(rec.X), e, np.zeros((pb.m, 1)))
        return k > 0 and lp <= np.log(alpha)

    return seen


def report(pb: Any, findings: list, records: list[OneStep], finding_cls: type,
           seen: Callable[[OneStep], bool], rms_ug: float) -> tuple[list, list[str]]:
    """The findings with the one-plateau structure reported, and the effects it lists.

    Kept: rejected effects no finding names or lists as a candidate, and — when other
    catalogue findings stand — that still explain structure after them (``seen``). With no
    other finding nothing is dropped: a family test significant at its level never ends in
    "consistent". The finding replaces an ``unexplained`` one that sits only at these
    plateaus (the scan found the same structure) and takes its place; otherwise it goes
    after the named findings.
    """
    covered = {f.effect for f in findings} | {
        c for f in findings for c in (f.where.get("candidates") or [])}
    named = [f for f in findings if f.effect != "unexplained"]
    keep = [r for r in sorted(records, key=lambda r: r.p_family)
            if r.effect_id not in covered and (not named or seen(r))]
    if not keep:
        return findings, []
    effects = list(dict.fromkeys(r.effect_id for r in keep))
    steps = sorted({r.step for r in keep})
    at = next((i for i, f in enumerate(findings) if f.effect == "unexplained"), len(findings))
    same = at < len(findings) and _only_at(findings[at], steps)
    f = _finding(pb, keep, effects, steps, findings[at] if same else None, finding_cls, rms_ug)
    out = findings[:at] + [f] + findings[at + (1 if same else 0):]
    return out, effects


def _only_at(unexplained: Any, steps: list[int]) -> bool:
    """An ``unexplained`` finding whose every place is one of ``steps`` (scan places only)."""
    places = unexplained.where.get("places") or []
    return bool(places) and all("step" in p and p["step"] in steps for p in places)


def _finding(pb: Any, keep: list[OneStep], effects: list[str], steps: list[int],
             replaced: Any, finding_cls: type, rms_ug: float) -> Any:
    """The ``not_identifiable`` finding: nothing is modelled, so RMS before = after."""
    ctx = pb.ctx
    temps = {s: ctx.step_temp_c.get(s, float("nan")) for s in steps}
    local = [f"a change confined to step {s} ({temps[s]:.0f} °C)" for s in steps]
    candidates = local + effects
    p_value = min(r.p_family for r in keep)
    rows = np.isin(ctx.steps, steps)
    span = [float(ctx.t_s[rows].min()), float(ctx.t_s[rows].max())]
    axes = sorted({a for r in keep for a in r.axes}, key=lambda a: (a not in AXES, a))
    found = ", ".join(f"{r.effect_id} at step {r.step} (p_family = {r.p_family:.2g})"
                      for r in keep)
    own = "; ".join(dict.fromkeys(BY_ID[e].experiment for e in effects if BY_ID[e].experiment))
    plateaus = "that plateau" if len(steps) == 1 else "those plateaus"
    text = (f"Structure beyond noise at {', '.join(f'step {s} ({temps[s]:.0f} °C)' for s in steps)}"
            f" on axis {'/'.join(axes)}: the family test found it ({found}); "
            f"{' or '.join(effects)} {'explains' if len(effects) == 1 else 'explain'} it, "
            f"but so does {' or '.join(local)} — a warm-up, "
            f"self-heating, a re-seat or an event on {plateaus} — and this protocol cannot "
            f"tell them apart (a free offset and gains of {plateaus} take the effect's "
            "evidence). It is neither named nor modelled. To separate them: "
            f"{SEPARATE}" + (f"; {own}" if own else "") + ".")
    where: dict[str, Any] = {"steps": steps, "positions": [], "time_s": span,
                             "candidates": candidates}
    if replaced is not None:
        where["places"] = replaced.where.get("places") or []
    return finding_cls(effect="not_identifiable", axes=axes, where=where, explanation=text,
                    parameters={}, parameter_sd={}, rmse_before_ug=rms_ug, rmse_after_ug=rms_ug,
                    heldout_rmse_before_ug=float("nan"), heldout_rmse_after_ug=float("nan"),
                    p_value=p_value, test=TEST)
