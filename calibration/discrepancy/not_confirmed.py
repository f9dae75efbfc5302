"""Structure the family test found whose term held-out data do not confirm: reported, not
dropped (issue 22).

Forward selection (diagnose.py, docs/diagnosis.md §5) adds the best candidate when its
family-wise p is ≤ α/2, and then asks held-out data (leave one step or interval out) to
confirm the term: a term that does not lower the held-out prediction error is not named.
Withholding the name is right: the effect, as modelled, does not predict readings it was
not fitted to. Dropping the structure was not: the family test had found it at the
verdict's level, and the verdict came out "consistent" (a table encoder error at twice its
detectable size, p_family = 1/401, "No mismatch: the residuals are consistent with noise").

Here each such rejection is recorded (:class:`NotConfirmed`) and, at the end, those no other
finding covers become one ``unexplained`` finding (:func:`report`) whose candidates are the
rejected effects: structure beyond noise, located, that no catalogue term explains in a way
that predicts held-out data. It re-labels structure the family test already found at α/2,
so the verdict's false-alarm level is unchanged in design: no new test decides a mismatch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from calibration.discrepancy.effects import BY_ID

TEST = "forward-selection family test; not named: its term does not predict held-out data"


@dataclass(frozen=True)
class NotConfirmed:
    """A candidate found by the family test whose term held-out data did not confirm."""

    effect_id: str
    p_family: float
    heldout_before_ug: float
    heldout_after_ug: float
    axes: tuple[str, ...]
    where: dict[str, Any]  # the term's places (locate.where_of)
    X: np.ndarray  # (m, k) the rejected term's unweighted columns (for one_step.still_seen)
    # Set when the term was not added because its fit, beyond the base model, lies within
    # an earlier term's columns (diagnose._outside_earlier_terms): that term, and the share
    # of the fit outside it.
    within: str | None = None
    share_outside: float = 1.0
    # Set when the held-out error was judged in units of the readings' noise, as the term's
    # test is (``CatalogueEffect.shrunk_heldout``): (without, with) the term. The µg figures
    # above can then fall while this rises; the sentence says which decided.
    heldout_noise_units: tuple[float, float] | None = None


def report(findings: list, records: list[NotConfirmed], finding_cls: type,
           seen: Callable[[Any], bool], rms_ug: float) -> list:
    """The findings with the unconfirmed structure reported.

    Kept: rejected effects that no finding names or lists as a candidate and — when named
    findings stand — that still explain structure after them (``seen``, as
    :func:`calibration.discrepancy.one_step.still_seen`). With no named finding nothing is
    dropped: a family test significant at its level never ends in "consistent". An
    ``unexplained`` finding already there (the scan located structure) takes the
    candidates and the sentence; otherwise a new one goes after the named findings.
    """
    covered = {f.effect for f in findings} | {
        c for f in findings for c in (f.where.get("candidates") or [])}
    named = [f for f in findings if f.effect not in ("unexplained", "not_identifiable")]
    keep = [r for r in sorted(records, key=lambda r: r.p_family)
            if r.effect_id not in covered and (not named or seen(r))]
    if not keep:
        return findings
    effects = list(dict.fromkeys(r.effect_id for r in keep))
    sentence = _sentence(keep, effects)
    at = next((i for i, f in enumerate(findings) if f.effect == "unexplained"), None)
    if at is not None:
        old = findings[at]
        where = {**old.where, "candidates": list(old.where.get("candidates") or []) + effects}
        findings = list(findings)
        findings[at] = replace(old, where=where, explanation=f"{old.explanation} {sentence}",
                                p_value=min(old.p_value, keep[0].p_family))
        return findings
    first = keep[0]
    where = {**first.where, "candidates": effects}
    axes = sorted({a for r in keep for a in r.axes})
    return [*findings, finding_cls(
        effect="unexplained", axes=axes, where=where, explanation=sentence, parameters={},
        parameter_sd={}, rmse_before_ug=rms_ug, rmse_after_ug=rms_ug,
        heldout_rmse_before_ug=first.heldout_before_ug,
        heldout_rmse_after_ug=first.heldout_after_ug, p_value=first.p_family, test=TEST)]


def _sentence(keep: list[NotConfirmed], effects: list[str]) -> str:
    """The finding's text: the records whose fit lay within an earlier term, then those
    held-out data did not confirm, each group naming only its own effects."""
    parts = []
    for group, say in (([r for r in keep if r.within], _within_sentence),
                       ([r for r in keep if not r.within], _heldout_sentence)):
        if group:
            ids = {r.effect_id for r in group}
            parts.append(say(group, [e for e in effects if e in ids]))
    return " ".join(parts)


def _heldout_sentence(keep: list[NotConfirmed], effects: list[str]) -> str:
    found = "; ".join(f"{r.effect_id} (p_family = {r.p_family:.2g}; {_heldout_figures(r)})"
                      for r in keep)
    own = "; ".join(dict.fromkeys(BY_ID[e].experiment for e in effects if BY_ID[e].experiment))
    return (f"Structure beyond noise that the family test found with the shape of {found}: "
            f"{'its term does' if len(keep) == 1 else 'none of their terms does'} not lower "
            f"the error of readings it was not fitted to, so {' or '.join(effects)} as "
            "modelled does not explain it, and it is neither named nor modelled. The "
            "structure is real at the verdict's level; what it is, this recording does not "
            "say" + (f". To test {'the candidate' if len(effects) == 1 else 'the candidates'}: "
                     f"{own}" if own else "") + ".")


def _heldout_figures(r: NotConfirmed) -> str:
    """The held-out figures that decided, in the units they were judged in."""
    ug = f"{r.heldout_before_ug:.4g} → {r.heldout_after_ug:.4g} µg"
    if r.heldout_noise_units is None:
        return f"held-out RMS {ug} with its term"
    before, after = r.heldout_noise_units
    return (f"held-out RMS in units of the readings' noise, as its test judges it, "
            f"{before:.4f} → {after:.4f} with its term; in µg {ug}")


def _within_sentence(keep: list[NotConfirmed], effects: list[str]) -> str:
    found = "; ".join(
        f"{r.effect_id} (p_family = {r.p_family:.2g}; {100 * (1 - r.share_outside):.1f} % of "
        f"its fit beyond the base model lies within the {r.within} term's columns)"
        for r in keep)
    return (f"Structure beyond noise that the family test found with the shape of {found}: "
            "fitted together, the terms cancel each other with coefficients far beyond the "
            "structure, so this recording cannot tell "
            f"{' or '.join(effects)} from "
            f"{' or '.join(dict.fromkeys(str(r.within) for r in keep))}, and "
            f"{'it is' if len(effects) == 1 else 'they are'} neither named nor modelled.")
