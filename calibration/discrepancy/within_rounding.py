"""A channel's finding within what its possible rounding can make: not established (issue 22).

A temperature channel quantised without dither records one code per settled plateau, and
its error there (code − die, within ±Q/2) is not random: a die that settles towards
setpoints on codes ends each plateau short of it, with the approach's sign on every plateau
of a leg — a step of the channel between the legs. Where the recording declares its LSB the
families take that error as a bound (stats.BoundedShared); where it shows a grid or writes
its codes finer than a degree, the null draws it at q²/12. Neither holds where the codes
admit a coarser LSB than the null uses: a channel whose every code is a whole degree (the die
settled on setpoints that lie on codes) could round at 1 °C or at 0.1 °C, and the recording
cannot say which (plateau_noise.admitted_lsb_c; docs/benchmarks.md: on the second
generator's 0.1 °C channel, 52 of 69 such recordings).

So the channel's own finding — a step of the channel (``temperature_sensor``) — is named
only when its evidence goes beyond the most any rounding within ±Q/2 per plateau and value,
at the coarsest LSB Q the codes admit, can put into its columns: the term's score ‖Bᵀe‖
(B its columns after the rest of the model, e the residual without it) shortened by the
box's reach (stats.BoundedShared.reach), against χ²ₖ at the level of the family test.
Otherwise it is not named and not modelled, and reported as not established with the
reason and what settles it: the LSB declared. A verdict on one finding, read only where the
LSB is not declared (a declared LSB's box is already in every family's test). Where Q is
coarser than the q the null draws, the localised scan takes each block's data score net of
the same box (:func:`coarser_box`, scan.scan(bounded=...)): without it the plateau a
withdrawn step leaves largest was reported ``unexplained`` (docs/benchmarks.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats as sps

from calibration.discrepancy import stats
from calibration.discrepancy.plateau_noise import admitted_lsb_c, rounding_box

# The channel's own findings: a pattern of the recorded temperature, which the rounding of
# a channel that does not dither makes itself (a step between legs).
CHANNEL_EFFECTS = ("temperature_sensor",)


@dataclass(frozen=True)
class WithinRounding:
    """A channel finding the rounding at the admitted LSB can make (:func:`within`)."""

    effect: str
    key: Any  # the term's key (diagnose.Term.key)
    q_c: float  # the coarsest LSB the codes admit, °C
    p_beyond: float  # the term's evidence net of the rounding's reach (χ²ₖ)
    reach: float | None  # one column: the most the rounding puts into its coefficient
    estimate: float | None  # one column: the fitted coefficient and its sd
    sd: float | None


@dataclass(frozen=True)
class Admitted:
    """The coarsest LSB a channel's codes admit and its rounding box (:func:`admitted`)."""

    q_c: float
    box: stats.BoundedShared


def admitted(pb: Any) -> Admitted | None:
    """The coarsest LSB the channel's codes admit (plateau_noise.admitted_lsb_c) and the box
    of any rounding within ±Q/2 per plateau and value through the base model
    (plateau_noise.rounding_box), read once per diagnosis; None where the recording has no
    temperature, the channel admits no LSB (dithered or continuous) or the base has no
    temperature dependence."""
    ctx = pb.ctx
    if ctx.temperature_source == "none":
        return None
    q = admitted_lsb_c(ctx.temp_c, ctx.steps)
    box = rounding_box(pb, q) if q is not None else None
    return None if box is None else Admitted(q, box)


def within(pb: Any, terms: list, level: float,
           basis: Callable[..., tuple[np.ndarray, np.ndarray]],
           admitted_q: Admitted | None, one_step: list | None = None) -> list[WithinRounding]:
    """The channel terms of ``terms`` (:data:`CHANNEL_EFFECTS`) whose evidence does not go
    beyond the rounding the channel's codes admit, at ``level``, each judged against the
    rest of the model; with ``one_step`` (one_step.OneStep records), those records instead,
    each judged against all of ``terms`` (a channel step withheld as one plateau's is the
    same structure, reported). ``basis(pb, terms)``: the orthonormal basis of the whitened
    design and the whitened data (diagnose._basis); ``admitted_q``: :func:`admitted`. Empty
    where no such term stands or the channel admits no LSB (a dithered or continuous
    channel)."""
    if one_step is None:
        cands = [(t.effect_id, t.key, t.X, [u for u in terms if u is not t])
                 for t in terms if t.effect_id in CHANNEL_EFFECTS and not t.rows]
    else:
        cands = [(r.effect_id, r, r.X, terms) for r in one_step
                 if r.effect_id in CHANNEL_EFFECTS]
    if not cands or admitted_q is None:
        return []
    q, box = admitted_q.q_c, admitted_q.box
    out: list[WithinRounding] = []
    for eid, key, X, others in cands:
        U, yw = basis(pb, others)
        e = yw - U @ (U.T @ yw)
        Xw = np.asarray(X, float) * pb.w[:, None]
        Xp = Xw - U @ (U.T @ Xw)
        B = stats.orthonormal_basis(Xp)
        k = B.shape[1]
        if k == 0:
            continue
        c = B.T @ e
        r = e - B @ c
        dof = np.sqrt(pb.m / max(pb.m - U.shape[1] - k, 1))
        s = float(stats.robust_scale(r[:, None], dof)[0])
        reach = box.reach(B)
        net = max(float(np.linalg.norm(c)) - reach, 0.0) / s if s > 0 else np.inf
        p = float(sps.chi2.sf(net**2, k))
        if p <= level:
            continue
        est = sd = reach_coef = None
        if Xp.shape[1] == 1:  # the coefficient's own units (a step in °C)
            norm = float(np.linalg.norm(Xp))
            if norm > 0:
                est = float(Xp[:, 0] @ e) / norm**2
                sd, reach_coef = s / norm, reach / norm
        out.append(WithinRounding(eid, key, q, p, reach_coef, est, sd))
    return out


def coarser_box(admitted_q: Admitted | None, shown_q_c: float | None
                ) -> stats.BoundedShared | None:
    """The rounding box at the coarsest LSB the channel's codes admit (``admitted_q``:
    :func:`admitted`), where that is coarser than the q the null already draws
    (``shown_q_c``: a grid's, or the held codes' written resolution; None: none drawn), for
    the scan's blocks (scan.scan(bounded=...)); None where it is not (or the channel admits
    no LSB). The caller takes it only where the LSB is not declared (a declared LSB is q
    itself)."""
    if admitted_q is None or (shown_q_c is not None
                              and admitted_q.q_c <= shown_q_c * (1.0 + 1e-6)):
        return None
    return admitted_q.box


def why(w: WithinRounding, source: str, lsb_column: str) -> str:
    """The reason given where the finding is not named (not_identifiable, notes)."""
    coarse = "every code a whole degree" if w.q_c >= 1.0 else f"its codes written to {w.q_c:g} °C"
    size = ""
    if w.estimate is not None and w.sd is not None and w.reach is not None:
        size = (f" (the fitted step {w.estimate:+.3f} ± {w.sd:.3f} °C, where a rounding error "
                f"within ±{w.q_c / 2:g} °C per plateau can make up to ±{w.reach:.3f} °C)")
    return (f"not established: within the channel's possible rounding{size}; the channel "
            f"({source}) does not dither and its readings admit an LSB of {w.q_c:g} °C "
            f"({coarse}), which the recording does not declare, so each plateau's "
            f"temperature is known to ±{w.q_c / 2:g} °C at best (p = {w.p_beyond:.2g} beyond "
            f"that rounding; declare {lsb_column})")
