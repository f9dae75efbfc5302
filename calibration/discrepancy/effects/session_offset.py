"""``session_offset``: a constant bias jump per power session (effects.md).

With a ``session`` column the sessions are known; otherwise the jump is
profiled over the plateau boundary where it occurred (one power cycle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, axis_params, fmt_pm, per_axis


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
    confusers: tuple[str, ...] = ("thermal_hysteresis", "bias_drift", "temperature_rate")
    experiment: str = ("power-cycle the sensor at one plateau and take the same positions "
                       "before and after the cycle")
    told_apart: tuple[tuple[str, str], ...] = (
        ("thermal_hysteresis",
         "a session jump happens once; hysteresis flips with each change of direction"),
        ("bias_drift", "a session offset is a step in time; drift is a ramp"),
        ("temperature_rate", "a rate term flips sign with the direction of the temperature "
                             "change; a session jump does not"),
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

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if ctx.session is not None and len(np.unique(ctx.session)) < 2:
            return False, "one continuous power session", self.experiment
        if ctx.session is None and len(ctx.step_ids) < 3:
            return False, "fewer than three plateaus: a jump is a temperature term", \
                self.experiment
        return True, "", self.experiment

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
