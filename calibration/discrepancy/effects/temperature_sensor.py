"""``temperature_sensor``: errors of the temperature channel the model reads (effects.md).

Two parts, told apart by what one temperature source can show:

* a constant offset and a curvature about 25 °C (:func:`channel_error_c`) re-map T
  smoothly; the cubic in T absorbs them completely, so they are not testable here;
* a **step** of the channel between plateaus (a re-zeroed or re-seated probe, a channel
  that jumped) is testable: from step k on the model reads ``T_rec = T_die + δ``, while the
  output still follows the die, so the raw output departs from the model by
  ``f(T_rec − δ) − f(T_rec) ≈ −δ · ∂f/∂T`` on those plateaus only. The regressor is the
  fitted base model's own ∂raw/∂T (Eq. 5's thermal polynomials differentiated, bias and
  scale terms alike) on the plateaus from k on; one parameter δ (°C), k profiled over the
  plateau boundaries. Its shape is locked to the model's temperature sensitivity, which
  is what tells it from a power-cycle bias jump (free per-axis biases, ``session_offset``).

A **glitch** of the channel on single readings (effects.md: "spikes in T") is the same
linearisation on one reading; the per-reading test finds it, and :mod:`.channel_glitch`
names it (the recorded temperature off its plateau neighbours, the residual along −∂f/∂T
with one δ), so it is not a grid value of this term.

What it cannot be told from (measured on the second generator, issue 22): a change confined
to one plateau. After the cubic in T the step's remnant lives in the n_plateaus − 4
dimensions the cubic leaves per column, and sits next to its boundary: a step from plateau 1
on *is* "plateau 0 differs" (the unshifted side is one plateau, even on an up-down
campaign), on a 5-temperature campaign every plateau's free block spans it, and on a 7-plateau
staircase the block of the plateau at the boundary takes 85–100 % of it. The column is the
step's shape there too (a refit on ``T − δ``, the exact f(T − δ) − f(T), moves its z by
≤ 0.1 and δ̂ by ≤ 1.3 sd); what fails is the separation, which ``diagnose``'s one-plateau check
decides, not this term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import CatalogueEffect

T_REF_SENSOR_C = 25.0  # the channel's curvature is about room temperature (effects.md)
MIN_PLATEAUS = 4  # a step at boundary k must leave ≥ 2 plateaus on one side for the cubic
# Why so close to 1: a channel step is a re-map of T, so the cubic absorbs nearly all of it
# by construction (99.9 % on an 8-plateau staircase); only the remnant can show it, and its
# test (same bootstrap null as every term) decides. The limit is the linearisation's own
# error: the regressor is ∂f/∂T·δ, not f(T − δ) − f(T), good to ~1 % in amplitude (10⁻⁴ in
# norm²) for a few °C on a cubic over ~100 °C; a remnant below that is not the step's shape
# (a warm-up on the first plateau left 2·10⁻⁶ and was taken for a step from plateau 1).
ABSORBED_MAX_STEP = 1.0 - 1e-4


def channel_error_c(die_c: np.ndarray, offset_c: float, k2_per_c: float) -> np.ndarray:
    """Temperature-channel error (N,) °C: ``offset_c + k2_per_c · (T_die − 25)²`` (effects.md)."""
    return offset_c + k2_per_c * (np.asarray(die_c, float) - T_REF_SENSOR_C) ** 2


def channel_step_c(steps: np.ndarray, from_step: float, step_c: float) -> np.ndarray:
    """Channel error (N,) °C of a step δ from plateau ``from_step`` on (the read − the die)."""
    return np.where(np.asarray(steps) >= from_step, float(step_c), 0.0)


@dataclass(frozen=True)
class TemperatureSensor(CatalogueEffect):
    effect_id: str = "temperature_sensor"
    twin_omitted: str = "an error of this recording's temperature channel, not of the sensor"
    # Why thermal_lag: a die soaked for several τ still lags the air by a remnant that is
    # nearly constant through each plateau and takes the sign of the last step; on an
    # up-down campaign that is a step of the channel at the turn (issue 22: a chamber-only
    # column on a 15 min die, soaked 6 τ, was named a channel step 6 times in 14).
    confusers: tuple[str, ...] = ("session_offset", "thermal_hysteresis", "self_heating",
                                  "thermal_lag")
    experiment: str = ("log a calibrated reference thermometer on the fixture next to the "
                       "temperature channel, or record chamber_c beside sensor_c")
    told_apart: tuple[tuple[str, str], ...] = (
        ("session_offset",
         "a channel step moves the output along the model's own ∂output/∂T (bias and scale "
         "terms together, one number for all axes and positions); a power-cycle jump is a "
         "free bias per axis, the same at every position"),
        ("thermal_hysteresis",
         "a channel step happens once and stays; hysteresis flips with each change of "
         "direction"),
        ("self_heating",
         "a steady die offset shifts every plateau alike (absorbed by the cubic); a channel "
         "step shifts only the plateaus after it"),
        ("thermal_lag",
         "a die lag's remnant scales with each step's size, takes each step's sign and decays "
         "through the plateau; a channel step is one constant on every plateau after it"),
    )
    absorbed_max: float = ABSORBED_MAX_STEP
    # Named by fit among its declared confusers (by_fit.py): its one column is the model's
    # own ∂raw/∂T times a step in time, comparable column for column with a lag's
    # (∂raw/∂T times the die–air difference) and the other thermal/time terms.
    named_by_fit: bool = True

    def grid(self, ctx: DesignContext) -> list[float]:
        return [float(s) for s in ctx.step_ids[1:]]

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        # Why the minus sign: the coefficient is the channel's step δ (read − die), and the
        # model evaluated at the read temperature is δ·∂f/∂T above what the die produced.
        on = channel_step_c(ctx.steps, theta, 1.0)
        return (-ctx.draw_dtemp_g_per_c * on[:, None])[:, :, None]

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if ctx.temperature_source == "none":
            return False, "no temperature is recorded", self.experiment
        if len(ctx.step_ids) < MIN_PLATEAUS:
            return (False, f"fewer than {MIN_PLATEAUS} plateaus: a step of the channel is a "
                    "re-mapping of T that the cubic absorbs (an offset or curvature of the "
                    "channel is, with one temperature source, always)", self.experiment)
        return True, "", self.experiment

    def misses(self, pb, U, e, theta, where, axes, alpha):
        """A step holds through each plateau: the channel's error must not change with time
        within the plateaus (a lagging or settling channel does; issue 22). Tested as the
        model's ∂raw/∂T times the time within each plateau (centred), after the term, with
        the noise read reading by reading (:func:`.structure.log_p_by_reading`): the column
        lives on the plateaus where ∂raw/∂T is large against the noise, the quiet ones,
        and a scale pooled over the recording ran it above its level there."""
        from calibration.discrepancy.effects.structure import log_p_by_reading, whitened

        ctx = pb.ctx
        frac = np.zeros(ctx.n)
        for s in ctx.step_ids:
            m = ctx.steps == s
            span = float(np.ptp(ctx.time_since_step_s[m]))
            if span > 0:
                frac[m] = ctx.time_since_step_s[m] / span - 0.5
        col = (ctx.draw_dtemp_g_per_c * frac[:, None])[:, :, None]
        lp, k = log_p_by_reading(pb, U, e, whitened(pb, col))
        if k == 0 or lp > np.log(alpha):
            return None
        steps = [int(s) for s in ctx.step_ids]
        return {"kind": "time", "steps": steps, "positions": [], "axes": list(axes),
                "time_s": [float(ctx.t_s.min()), float(ctx.t_s.max())],
                "log10_p": float(lp / np.log(10)),
                "why": ("a step of the temperature channel holds through each plateau, but "
                        "the output departs from the model along ∂output/∂T with time within "
                        "the plateaus (a lagging or settling channel, not a step)")}

    def parameters(self, coef, se, theta, ctx):
        return ({"step_c": float(coef[0]), "from_step": float(theta)},
                {"step_c": float(se[0]), "from_step": 0.0})

    def axes(self, coef, se):
        return ["x", "y", "z"]

    def sentence(self, params, sd, axes, ctx=None):
        src = ctx.temperature_source if ctx is not None else "temperature"
        return (f"the temperature channel ({src}) reads {params['step_c']:+.2f} ± "
                f"{sd['step_c']:.2f} °C off from step {int(params['from_step'])} on, while the "
                "output follows the die as before (a re-zeroed or re-seated channel); a constant "
                "offset or curvature of the channel is not testable with one temperature source")
