"""A flagged reading: a glitch of the temperature channel, an ``outlier``, or not separable.

``temperature_sensor`` (effects.md: "stair steps or spikes in T") includes a **glitch**: the
recorded temperature of one reading is off by δ while the output still follows the die. The
model evaluated at the wrong temperature leaves that reading a residual
``f(T_rec − δ) − f(T_rec) ≈ −δ · ∂f/∂T`` (the same linearisation as the channel step,
:mod:`~calibration.discrepancy.effects.temperature_sensor`, with the fitted base model's own
∂raw/∂T, Eq. 5's thermal polynomials differentiated), and the per-reading test flags it
like a shock. Two things the data show tell them apart (issue 22):

1. **the channel departs**: a die cannot jump, so the recorded temperature of a glitched
   reading departs from a straight line through its neighbours in time on the same plateau
   (:func:`temperature_departure`) by ``d ± sd`` far beyond the channel's own scatter;
2. **the output has the glitch's shape**: the reading's residual is ``−δ · ∂f/∂T`` on all
   its axes with ONE scalar δ (°C): fitted, ``δ̂ ± σ_δ``, nothing left beside it (the
   reading's other dof, a single F test at α), and δ̂ agrees with ``d``.

:func:`decide` states the verdict: ``temperature_sensor`` when both hold and the departure
alone would move the output beyond its noise; ``outlier`` when the residual is not along
∂f/∂T or the recorded temperature excludes the δ it would need (a shock at a normal
temperature); not separable when the residual is along ∂f/∂T but the temperature cannot
decide (too few neighbours on the plateau, a departure within the channel's scatter, or a
model too flat in T for the departure to show in the output).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import norm

from calibration.discrepancy import stats
from calibration.discrepancy.effects.structure import extend, log_p, per_axis_indicator, whitened

GLITCH = "temperature_sensor"
OUTLIER = "outlier"
NOT_SEPARABLE = "not_separable"
# Readings of the same plateau a local line of the temperature is drawn through: the nearest
# in time (a die on a plateau moves slowly; a line over the whole plateau misses a settling
# start), at least MIN_NEIGHBOURS (a line through fewer predicts the reading's temperature
# no better than the channel's scatter, and its own scatter cannot be judged).
NEIGHBOURS = 8
MIN_NEIGHBOURS = 4
# Neighbours farther than this many (scatter + quantum) from the first line are left out
# of the second (another glitch among them), as temperature_conditioning does.
REJECT_SIGMAS = 4.0


@dataclass(frozen=True)
class Departure:
    """The recorded temperature of a reading against a line through its plateau neighbours."""

    departure_c: float  # recorded − line at the reading's time
    sd_c: float  # of the departure under "no glitch": the channel's scatter and the line's
    line_sd_c: float  # of the line's value alone (the reading's own channel noise excluded)
    n_neighbours: int


@dataclass(frozen=True)
class GlitchCheck:
    """What one flagged reading shows (see the module docstring) and the verdict."""

    row: int
    verdict: str  # GLITCH | OUTLIER | NOT_SEPARABLE
    why: str
    delta_c: float  # δ̂ fitted to the reading's residual along −∂f/∂T
    delta_sd_c: float
    remainder_log10_p: float | None  # the residual beside δ̂ (None: no dof left, norm mode)
    departure: Departure | None

    def to_json(self) -> dict[str, Any]:
        d = self.departure
        return {"row": self.row, "glitch_c": _g(self.delta_c), "glitch_sd_c": _g(self.delta_sd_c),
                "channel_departure_c": None if d is None else _g(d.departure_c),
                "channel_departure_sd_c": None if d is None else _g(d.sd_c),
                "remainder_log10_p": (None if self.remainder_log10_p is None
                                      else round(self.remainder_log10_p, 1)),
                "verdict": self.verdict, "why": self.why}


def _g(v: float) -> float | None:
    return float(f"{v:.4g}") if np.isfinite(v) else None


def channel_scatter_c(ctx: Any) -> float:
    """Reading-to-reading scatter of the recorded temperature (°C), floored by its quantum.

    The robust sd of first differences within each plateau / √2, the median over plateaus
    (``problem.temperature_noise_c``), but never below a quantised channel's rounding
    error quantum/√12 (``temperature_conditioning.channel_quantum_c``): a channel read in
    0.11 °C steps can show no difference at all between most neighbours.
    """
    from calibration.discrepancy.problem import temperature_noise_c
    from calibration.temperature_conditioning import channel_quantum_c

    pooled = float(temperature_noise_c(ctx)[0]) if ctx.n else 0.0
    return max(pooled, channel_quantum_c(ctx.temp_c) / np.sqrt(12.0))


def temperature_departure(ctx: Any, row: int, skip: set[int],
                          scatter_c: float | None = None) -> Departure | None:
    """The recorded temperature at ``row`` against a line through its neighbours (None:
    no temperature, or fewer than :data:`MIN_NEIGHBOURS` on its plateau).

    The :data:`NEIGHBOURS` readings nearest in time on the same plateau, ``skip`` (other
    flagged readings) left out, a least-squares line of temperature against time, refitted
    without neighbours beyond :data:`REJECT_SIGMAS` × (scatter + quantum) as
    ``temperature_conditioning.condition_temperature`` does. Scatter: the larger of the
    channel's (:func:`channel_scatter_c`) and the neighbours' robust scatter about the line
    (a wandering channel predicts its next reading less well).
    """
    if ctx.temperature_source == "none":
        return None
    on = np.flatnonzero(ctx.steps == ctx.steps[row])
    on = np.array([j for j in on if j != row and j not in skip], int)
    if on.size < MIN_NEIGHBOURS:
        return None
    near = on[np.argsort(np.abs(ctx.t_s[on] - ctx.t_s[row]), kind="stable")[:NEIGHBOURS]]
    tt = ctx.t_s[near] - ctx.t_s[row]
    yy = ctx.temp_c[near]
    base = channel_scatter_c(ctx) if scatter_c is None else scatter_c
    keep = np.ones(near.size, bool)
    for _ in range(2):
        V = np.column_stack([np.ones(keep.sum()), tt[keep]]) if np.ptp(tt[keep]) > 0 else \
            np.ones((keep.sum(), 1))
        coef = np.linalg.lstsq(V, yy[keep], rcond=None)[0]
        res = yy - (coef[0] + (coef[1] * tt if coef.size > 1 else 0.0))
        sd = max(base, 1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep])))))
        far = np.abs(res) > REJECT_SIGMAS * (sd + base)
        if not far.any() or (~far).sum() < MIN_NEIGHBOURS or np.array_equal(keep, ~far):
            break
        keep = ~far
    k = int(keep.sum())
    x = tt[keep]
    sxx = float(np.sum((x - x.mean()) ** 2))
    lev = 1.0 / k + (x.mean() ** 2 / sxx if coef.size > 1 and sxx > 0 else 0.0)
    departure = float(ctx.temp_c[row] - coef[0])
    return Departure(departure, sd * float(np.sqrt(1.0 + lev)), sd * float(np.sqrt(lev)), k)


# Below this recorded departure (°C) the tangent is the glitch's shape to rounding.
SECANT_MIN_C = 1e-3


def glitch_column(ctx: Any, row: int, departure_c: float | None = None) -> np.ndarray:
    """(N,3,1) raw-output column of a glitch δ = 1 °C of the channel on ``row`` (the
    coefficient is δ, read − die, as for the channel step): −∂raw/∂T there.

    With the recorded departure ``d``, the secant instead: the base with that reading at
    ``T − d``, its output change there over ``d`` (reference mode: the base refitted so,
    ``ctx.refit_shift``; norm mode: the fitted base evaluated there, ``ctx.temperature_shift``).
    Why: a glitch of several °C on a cubic is not linear in δ to the output's noise (a 6 °C
    glitch left 1 mg at one reading, and its direction turned by the axes' curvatures).
    """
    out = np.zeros((ctx.n, 3, 1))
    out[row, :, 0] = -ctx.draw_dtemp_g_per_c[row]
    if departure_c is None or abs(departure_c) <= SECANT_MIN_C:
        return out
    dT = np.zeros(ctx.n)
    dT[row] = -departure_c
    if ctx.refit_shift is not None:
        out[row, :, 0] = ctx.refit_shift(dT)[0][row] / departure_c
    elif ctx.temperature_shift is not None:
        out[row, :, 0] = ctx.temperature_shift(dT)[row] / departure_c
    return out


def check_reading(pb: Any, U: np.ndarray, e: np.ndarray, row: int, skip: set[int],
                  alpha: float) -> GlitchCheck | None:
    """Glitch or outlier at a flagged ``row`` (module docstring); None when the model has no
    temperature dependence there (a channel error cannot move its output).

    ``U``, ``e``: the whitened model without any flagged reading's term and its residual.
    """
    ctx = pb.ctx
    if ctx.temperature_source == "none" or not np.any(ctx.draw_dtemp_g_per_c[row]):
        return None
    dep = temperature_departure(ctx, row, skip)
    xw = whitened(pb, glitch_column(ctx, row, None if dep is None else dep.departure_c))
    z = stats.project_out(U, xw)[:, 0]
    zz = float(z @ z)
    dof = np.sqrt(pb.m / max(pb.m - U.shape[1], 1))
    s = float(stats.robust_scale(e[:, None], dof)[0])
    delta, delta_sd = (float(z @ e) / zz, s / np.sqrt(zz)) if zz > 0 else (np.nan, np.inf)
    Ug, eg = extend(U, e, xw)
    lp, k = log_p(Ug, eg, whitened(pb, per_axis_indicator(ctx.n, np.array([row]))))
    rem = float(lp / np.log(10)) if k else None
    verdict, why = decide(dep, delta, delta_sd, rem, alpha)
    return GlitchCheck(row, verdict, why, delta, delta_sd, rem, dep)


def decide(dep: Departure | None, delta_c: float, delta_sd_c: float,
           remainder_log10_p: float | None, alpha: float) -> tuple[str, str]:
    """The verdict on one flagged reading and the reason (single tests at α, two-sided z).

    * ``outlier``: the residual beside δ̂ is significant (not along ∂output/∂T), or the
      recorded temperature excludes the δ̂ the output would need (|δ̂ − d| beyond z·√(σ_δ²
      + sd_line²); the reading's own channel noise is in both and cancels);
    * ``temperature_sensor``: the residual is along ∂output/∂T, δ̂ agrees with d, the
      temperature departs (|d| > z·sd) and that departure alone would move the output
      beyond its noise (|d| > z·σ_δ);
    * not separable otherwise: along ∂output/∂T, and the temperature cannot decide.
    """
    z = float(norm.isf(alpha / 2))
    if not np.isfinite(delta_c) or (remainder_log10_p is not None
                                    and remainder_log10_p <= np.log10(alpha)):
        return OUTLIER, ("its deviation is not along the model's own ∂output/∂T (one "
                         "temperature error δ on all axes leaves a residual beside it)")
    if dep is None:
        return NOT_SEPARABLE, (
            f"its deviation is along ∂output/∂T (δ = {delta_c:+.2f} ± {delta_sd_c:.2f} °C), "
            f"and its plateau holds fewer than {MIN_NEIGHBOURS} other readings to tell whether "
            "its recorded temperature departs from the die's")
    d = dep.departure_c
    if abs(delta_c - d) > z * np.hypot(delta_sd_c, dep.line_sd_c):
        return OUTLIER, (
            f"the output would need the temperature {delta_c:+.2f} ± {delta_sd_c:.2f} °C off, "
            f"the recorded temperature departs {d:+.2f} ± {dep.sd_c:.2f} °C from its "
            "neighbours: the temperature does not explain it")
    shows = (f"the recorded temperature departs {d:+.2f} ± {dep.sd_c:.2f} °C from its "
             f"neighbours on the plateau and the output departs along ∂output/∂T by δ = "
             f"{delta_c:+.2f} ± {delta_sd_c:.2f} °C")
    if abs(d) <= z * dep.sd_c:
        return NOT_SEPARABLE, (f"{shows}, but that departure is within the channel's own "
                               "scatter: a glitch of the channel or an output off by as much")
    if abs(d) <= z * delta_sd_c:
        return NOT_SEPARABLE, (f"{shows}, but the model is too flat in temperature here for "
                               "that departure to move the output beyond its noise: the "
                               "shape cannot tell a glitch from an output off by as much")
    return GLITCH, shows


EXPERIMENT = ("log a calibrated reference thermometer on the fixture next to the temperature "
              "channel (or record chamber_c beside sensor_c), and repeat the flagged positions")
TOLD_APART = ("a glitch of the channel moves the recorded temperature of the reading off its "
              "neighbours and the output along the model's own ∂output/∂T by the same δ; an "
              "outlier moves the output alone, in any direction, at a normal temperature")


def restate(findings: list[Any], checks: dict[int, GlitchCheck | None], ctx: Any,
            not_ident: dict[str, dict[str, str]]) -> list[Any]:
    """The ``outlier`` findings as their readings' checks state them (issue 22).

    A finding (a ``diagnose.Finding``, one per flagged reading at this stage) whose reading
    the check calls a glitch becomes ``temperature_sensor`` (δ ± sd in °C, the reading, the
    channel's departure); one it cannot decide becomes ``not_identifiable`` with both
    candidates (both entered in ``not_ident``). Either way the reading's term stays: the
    reading is excluded from the kept model, its temperature is not repaired. Readings with
    the same verdict are merged into one finding; the others stay ``outlier``.
    """
    out: list[Any] = []
    for f in findings:
        cs = ([checks.get(r) for r in f.rows] if f.effect == OUTLIER and f.named_as_modelled
              and f.rows else [])
        verdicts = {c.verdict if c is not None else OUTLIER for c in cs}
        if not cs or len(verdicts) != 1 or OUTLIER in verdicts:
            out.append(f)
            continue
        checked = [c for c in cs if c is not None]
        where = {**f.where, "rows": list(f.rows), "glitches": [c.to_json() for c in checked]}
        if verdicts == {GLITCH}:
            c = checked[0]
            params = {"glitch_c": c.delta_c, **{k: f.parameters[k] for k in
                                                ("row", "t_s", "step", "position")
                                                if k in f.parameters}}
            sd = {"glitch_c": c.delta_sd_c}
            if c.departure is not None:
                params["channel_departure_c"] = c.departure.departure_c
                sd["channel_departure_c"] = c.departure.sd_c
            out.append(replace(
                f, effect=GLITCH, axes=["x", "y", "z"], where=where,
                parameters={k: float(f"{v:.4g}") for k, v in params.items()},
                parameter_sd={k: float(f"{v:.4g}") for k, v in sd.items()},
                confusers=[{"effect": OUTLIER, "p_before": None, "p_after": None,
                            "how_told_apart": TOLD_APART}]))
        else:
            candidates = [GLITCH, OUTLIER]
            for cand in candidates:
                other = OUTLIER if cand == GLITCH else GLITCH
                not_ident.setdefault(cand, {
                    "effect": cand, "why": f"not separable from {other} at the flagged "
                    f"reading(s): {checked[0].why}", "experiment": EXPERIMENT})
            out.append(replace(f, effect="not_identifiable", where={**where,
                               "candidates": candidates}, parameters={}, parameter_sd={},
                               confusers=[]))
    return [_with_sentence(f, ctx) for f in _merged(out)]


def _merged(findings: list[Any]) -> list[Any]:
    """Findings of one verdict over several readings become one, at the first's place."""
    out: list[Any] = []
    for f in findings:
        if "glitches" not in f.where:
            out.append(f)
            continue
        prev = next((g for g in out if "glitches" in g.where and g.effect == f.effect), None)
        if prev is None:
            out.append(f)
            continue
        w, v = prev.where, f.where
        merged_where = {**w, "steps": sorted(set(w["steps"]) | set(v["steps"])),
                        "positions": sorted(set(w["positions"]) | set(v["positions"])),
                        "time_s": [min(w["time_s"][0], v["time_s"][0]),
                                   max(w["time_s"][1], v["time_s"][1])],
                        "rows": w["rows"] + v["rows"], "glitches": w["glitches"] + v["glitches"]}
        out[out.index(prev)] = replace(prev, where=merged_where, rows=prev.rows + f.rows,
                                       rmse_after_ug=f.rmse_after_ug,
                                       heldout_rmse_after_ug=f.heldout_rmse_after_ug)
    return out


def _with_sentence(f: Any, ctx: Any) -> Any:
    """The explanation of a restated finding, from all its readings' checks."""
    if "glitches" not in f.where:
        return f
    g = f.where["glitches"]
    rows = f.where["rows"]
    params = ({**f.parameters, "n_rows": float(len(rows))} if f.parameters and len(rows) > 1
              else f.parameters)
    if f.effect == GLITCH:
        each = "; ".join(_reading_text(j, ctx) for j in g)
        text = (f"The temperature channel ({ctx.temperature_source}) read off the die on "
                f"{len(rows)} reading(s) while the output followed the die: {each}. A die's "
                "temperature cannot jump; these are glitches of the channel (not outliers of "
                "the output). The readings are excluded from the kept model (their "
                "temperatures are not repaired).")
    else:
        each = "; ".join(f"{_at(int(j['row']), ctx)}: {j['why']}" for j in g)
        text = (f"{len(rows)} reading(s) stand far off the rest; a glitch of the temperature "
                "channel (temperature_sensor) or an output off by as much (outlier) explain "
                f"them alike here: {each}. The readings are excluded from the kept model. To "
                f"separate them: {EXPERIMENT}.")
    return replace(f, explanation=text, parameters=params)


def _at(r: int, ctx: Any) -> str:
    return f"reading {r} (t = {ctx.t_s[r]:.0f} s, step {int(ctx.steps[r])})"


def _reading_text(j: dict[str, Any], ctx: Any) -> str:
    at = _at(int(j["row"]), ctx)
    dep = ("too few neighbours to judge its temperature" if j["channel_departure_c"] is None
           else f"recorded temperature {j['channel_departure_c']:+.2f} ± "
                f"{j['channel_departure_sd_c']:.2f} °C off its neighbours")
    fit = ("output off the model along ∂output/∂T by δ = "
           f"{j['glitch_c']:+.2f} ± {j['glitch_sd_c']:.2f} °C" if j["glitch_c"] is not None
           else "no temperature sensitivity to fit")
    return f"{at}: {dep}, {fit}"
