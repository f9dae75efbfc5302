"""``session_offset``: a constant bias jump per power session (effects.md).

With a ``session`` column the sessions are known; otherwise the jump is
profiled over the plateau boundary where it occurred (one power cycle).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, axis_params, fmt_pm, per_axis

MIN_SIDE_READINGS = 3  # a jump inside a plateau leaves at least this many readings each side


def session_offset_g(session: np.ndarray, offsets_g: np.ndarray) -> np.ndarray:
    """Session-offset output change (N,3) g: ``offsets_g[session]`` (effects.md).

    ``session`` (N,) integer power-session index per reading, ``offsets_g`` (S,3)
    one bias per session (this module reports the later sessions' offsets
    relative to the first, i.e. ``offsets_g[0] = 0``).
    """
    off = np.atleast_2d(np.asarray(offsets_g, float))
    s = np.asarray(session)
    if s.max(initial=0) >= off.shape[0]:
        raise ValueError(f"offsets_g has {off.shape[0]} sessions, readings reach "
                         f"session {int(s.max())}")
    return off[s]


@dataclass(frozen=True)
class SessionOffset(CatalogueEffect):
    effect_id: str = "session_offset"
    twin_omitted: str = "a power cycle of this recording, not physics a new campaign repeats"
    confusers: tuple[str, ...] = ("thermal_hysteresis", "bias_drift", "temperature_rate",
                                  "vibration_rectification")
    experiment: str = ("power-cycle the sensor at one plateau and take the same positions "
                       "before and after the cycle")
    told_apart: tuple[tuple[str, str], ...] = (
        ("thermal_hysteresis",
         "a session jump happens once; hysteresis flips with each change of direction"),
        ("bias_drift", "a session offset is a step in time; drift is a ramp"),
        ("temperature_rate", "a rate term flips sign with the direction of the temperature "
                             "change; a session jump does not"),
        ("vibration_rectification",
         "a rectified offset follows the vibration power recorded in sd_* on every plateau; a "
         "power cycle is a step with no recorded cause. Where the vibration power changes at "
         "the jump's boundary and nowhere else, the two are one step and not separable"),
    )
    writes_extension: bool = True
    named_by_fit: bool = True

    def grid(self, ctx: DesignContext) -> list[float]:
        if ctx.session is not None:
            return [float("nan")]
        return [float(s) for s in ctx.step_ids[1:]]

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        if ctx.session is not None:
            first = ctx.session[0]
            levels = [s for s in np.unique(ctx.session) if s != first]
            cols = [per_axis(ctx, (ctx.session == s).astype(float)) for s in levels]
            return np.concatenate(cols, axis=2) if cols else np.zeros((ctx.n, 3, 0))
        return per_axis(ctx, (ctx.steps >= theta).astype(float))

    def cause_recorded(self, ctx: DesignContext) -> bool:
        """A ``session`` column logs the power cycles: the operator's act, not the
        temperature's."""
        return ctx.session is not None

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if ctx.session is not None and len(np.unique(ctx.session)) < 2:
            return False, "one continuous power session", self.experiment
        if ctx.session is None and len(ctx.step_ids) < 3:
            return False, "fewer than three plateaus: a jump is a temperature term", \
                self.experiment
        return True, "", self.experiment

    def misses(self, pb: Any, U: np.ndarray, e: np.ndarray, theta: float,
               where: Mapping[str, Any], axes: list[str], alpha: float) -> dict[str, Any] | None:
        """A jump inside a plateau, not between two: :func:`jump_inside_plateau`."""
        if pb.ctx.session is not None or not np.isfinite(theta):
            return None
        return jump_inside_plateau(pb, U, e, int(theta), axes, alpha)

    def not_told_from(self, pb, U, e, X, theta, alpha):
        """``vibration_rectification`` when the jump's plateau is where the recorded
        vibration power steps, and the vibration does nothing else (issue 22).

        Without a session column the jump's cause is not recorded; the vibration's is. A
        rectified offset then is the same step, and the step fits a little better only
        because each reading's ``sd²`` carries its own sampling error (a rectified offset on
        the project's blind set was named a power cycle 5 times in 9). The jump is not
        named alone there, whatever the fits.
        """
        from calibration.discrepancy.effects.vibration_rectification import power_step

        if pb.ctx.session is not None or not np.isfinite(theta):
            return [], ""
        if power_step(pb.ctx) != int(theta):
            return [], ""
        return ["vibration_rectification"], (
            f"the recorded vibration power (sd_*) steps at the same plateau ({int(theta)}) "
            "and nowhere else: a rectified offset and a power cycle there are one step, and "
            "the recording holds no session column to say a power cycle happened")

    def parameters(self, coef, se, theta, ctx):
        p, s = axis_params("offset", "ug", coef[:3], se[:3], UG)
        if np.isfinite(theta):
            p["from_step"], s["from_step"] = float(theta), 0.0
        return p, s

    def sentence(self, params, sd, axes, ctx=None):
        parts = [fmt_pm(params[f"offset_{a}_ug"], sd[f"offset_{a}_ug"], "µg") for a in axes]
        if "from_step" in params:
            # Why: without a session column the jump is seen, its cause is not recorded.
            return (f"{'/'.join(axes)} bias jumps by {', '.join(parts)} from step "
                    f"{int(params['from_step'])} on and stays there, as after a power cycle (the "
                    "recording has no session column, so its cause is not recorded)")
        return (f"{'/'.join(axes)} bias jumps by {', '.join(parts)} in the later power "
                "session(s) of the session column and stays there")


def jump_inside_plateau(pb: Any, U: np.ndarray, e: np.ndarray, from_step: int,
                        axes: list[str], alpha: float) -> dict[str, Any] | None:
    """Where the data put the jump inside plateau ``from_step`` − 1 or ``from_step``, or
    None (issue 22).

    Without a session column the jump is profiled over plateau boundaries: a power cycle
    between two plateaus. A change of the sensor during a plateau (a crack, a shift of the
    mount) fits that jump at the nearest boundary and leaves the readings between the change
    and the boundary off. Tested after the model (``U``, ``e``: the model with the jump):
    for each reading of the two plateaus with at least :data:`MIN_SIDE_READINGS` readings
    of its plateau before and after it, a per-axis offset of the readings between it and
    the boundary (F test on the term's axes, after a per-axis slope in the plateau's own
    temperature and one in time on each of the two plateaus), the smallest p
    Šidák-adjusted over those readings. A jump at the boundary leaves nothing there but
    noise (rejected with probability α). Returns the place (the two plateaus, the
    readings moved, log10 p).
    """
    from calibration.discrepancy.effects.structure import (
        extend,
        log_p,
        per_axis_indicator,
        whitened,
    )

    ctx = pb.ctx
    ids = list(ctx.step_ids)
    if from_step not in ids or ids.index(from_step) == 0:
        return None
    before = ids[ids.index(from_step) - 1]
    ax = tuple(AXES.index(a) for a in axes if a in AXES) or (0, 1, 2)
    segments: list[np.ndarray] = []
    for step, later in ((before, False), (from_step, True)):
        rows = np.flatnonzero(ctx.steps == step)
        rows = rows[np.argsort(ctx.t_s[rows], kind="stable")]
        for i in range(MIN_SIDE_READINGS, rows.size - MIN_SIDE_READINGS + 1):
            # jump earlier (inside ``before``): its readings from i on are off;
            # jump later (inside ``from_step``): its readings before i are off
            segments.append(rows[:i] if later else rows[i:])
    if not segments:
        return None
    # What a temperature that moves within a plateau leaves (a settling die, a rate
    # effect, a channel that ramps while the output does not), and a slow trend in time
    # on it, are in the model first: per axis, a slope in each plateau's own temperature
    # and one in time. What is tested is a step beyond both (a crack, not a settling).
    k = len(ax)
    within = np.zeros((ctx.n, 3, 4 * k))
    for i, step in enumerate((before, from_step)):
        rows = ctx.steps == step
        on = per_axis_indicator(ctx.n, np.flatnonzero(rows), ax)
        for j, v in enumerate((ctx.temp_c, ctx.t_s)):
            dv = np.where(rows, v - v[rows].mean(), 0.0)
            within[:, :, (2 * i + j) * k:(2 * i + j + 1) * k] = on * dv[:, None, None]
    U, e = extend(U, e, whitened(pb, within))
    lps = np.array([log_p(U, e, whitened(pb, per_axis_indicator(ctx.n, seg, ax)))[0]
                    for seg in segments])
    j = int(np.argmin(lps))
    lp_adj = float(stats.sidak_log(lps[j], len(segments)))  # over the readings tried
    if lp_adj > np.log(alpha):
        return None
    seg = segments[j]
    step = int(ctx.steps[seg[0]])
    t0, t1 = float(ctx.t_s[seg].min()), float(ctx.t_s[seg].max())
    return {"kind": "time", "steps": sorted({before, from_step}),
            "positions": sorted({int(p) for p in ctx.positions[seg]}),
            "time_s": [t0, t1], "axes": [AXES[a] for a in ax],
            "log10_p": round(lp_adj / np.log(10), 1),
            "why": (f"the data put the jump inside plateau {step}, between t = {t0:.0f} and "
                    f"{t1:.0f} s (its readings there are off by the jump), not between two "
                    "plateaus as a power cycle would: a change of the sensor during a "
                    "plateau (a mechanical shift, a crack) is not a catalogue effect; if the "
                    "sensor was power-cycled then, a session column would say so")}
