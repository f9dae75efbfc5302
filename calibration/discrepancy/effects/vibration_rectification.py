"""``vibration_rectification``: an offset ∝ the within-window variance (effects.md).

Regressor per axis: the vibration power of each reading, estimated from the recorded
``sd_a²`` (g²) (:func:`vibration_power_g2`). Without ``sd_*`` it cannot be seen; when the
vibration follows temperature the cubic absorbs it.

Why not ``sd_a²`` as recorded: each reading's ``sd²`` is an estimate from its own window,
with a relative sd of √(2/(n−1)) (10 % at n = 200). The offset follows the window's
power, not that sampling error; a regressor carrying it explains less of a rectified
offset than a clean step does, and a power cycle at the boundary where the compressor
stops was named over the vibration that the recording shows there (issue 22, 5 of 9 on the
project's blind set). Within each plateau the deviations from the plateau's mean are shrunk
by the share of their scatter that sampling explains (a positive-part James–Stein factor):
a vibration that really varies within a plateau keeps its variation, sampling noise does not."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import CatalogueEffect, axis_params, fmt_pm


def rectified_offset_g(sd_vib_g: np.ndarray, c_per_g: np.ndarray) -> np.ndarray:
    """Vibration-rectification output change (N,3) g: ``c_i × σ²`` (effects.md).

    ``sd_vib_g`` is the vibration in g rms, one per reading (N,) acting on every
    axis (the twin's rig vibration) or per axis (N,3) (the recorded ``sd_*``);
    ``c_per_g`` one value or (3,).
    """
    sd = np.asarray(sd_vib_g, float)
    c = np.broadcast_to(np.asarray(c_per_g, float), (3,))
    return (sd**2 if sd.ndim == 2 else (sd**2)[:, None]) * c[None, :]


def vibration_power_g2(ctx: DesignContext) -> np.ndarray:
    """(N,3) vibration power per reading and axis (g²), from the recorded ``sd_*``.

    Per plateau and axis: the plateau's mean ``sd²`` plus each reading's deviation from it
    times ``λ = max(0, 1 − Σ var_i (1 − 1/k) / Σ dev²)``, with ``var_i = 2 sd_i⁴/(n_i − 1)``
    the sampling variance of a variance estimated from ``n_i`` white samples, over the
    plateau's ``k`` readings. Without the ``n`` column the scatter cannot be split and the
    recorded ``sd²`` is used as is. A vibration correlated over many samples has fewer
    effective degrees of freedom than ``n − 1``; λ is then larger than it should be, so the
    shrinkage errs towards keeping the recorded scatter.
    """
    assert ctx.sd_g is not None
    x = ctx.sd_g**2
    if ctx.n_samples is None:
        return x
    out = x.copy()
    for s in ctx.step_ids:
        rows = np.flatnonzero(ctx.steps == s)
        n = ctx.n_samples[rows]
        ok = np.isfinite(n)
        if rows.size < 2 or not np.any(ok):
            continue
        m = x[rows].mean(axis=0)
        dev = x[rows] - m
        var = 2.0 * x[rows][ok] ** 2 / (n[ok, None] - 1.0)
        noise = var.mean(axis=0) * (rows.size - 1)
        ss = np.sum(dev**2, axis=0)
        lam = np.where(ss > 0, np.clip(1.0 - noise / np.where(ss > 0, ss, 1.0), 0.0, 1.0), 0.0)
        out[rows] = m + lam * dev
    return out


# A vibration power that changes beyond its one step by less than this share of the step
# (between plateau means) cannot tell a rectified offset from a jump at that step.
STEP_ONLY_SHARE = 0.1
STEP_MIN_Z = 5.0  # the step of the plateau means, in their standard errors, to count


def power_step(ctx: DesignContext) -> int | None:
    """The plateau from which the recorded vibration power steps, when that one step is all
    it does; else None (no ``sd_*``, no clear step, or changes at other plateaus too).

    From the plateau means of ``sd²`` per axis, each with its standard error (the scatter
    within the plateau over √k): the best split into two levels (before/after one plateau
    boundary) must move some axis by ≥ :data:`STEP_MIN_Z` standard errors, and no plateau
    may then depart from its level by more than 3 standard errors and
    :data:`STEP_ONLY_SHARE` of that axis' step. This is a fact of the design (what the
    vibration did), not a test of the output.
    """
    if ctx.sd_g is None or len(ctx.step_ids) < 3:
        return None
    ids = list(ctx.step_ids)
    x = ctx.sd_g**2
    m = np.array([x[ctx.steps == s].mean(axis=0) for s in ids])
    k = np.array([np.sum(ctx.steps == s) for s in ids], float)
    se = np.array([x[ctx.steps == s].std(axis=0, ddof=1) if c > 1 else np.full(3, np.inf)
                   for s, c in zip(ids, k, strict=True)]) / np.sqrt(k)[:, None]
    se = np.where(np.isfinite(se) & (se > 0), se, np.nanmax(np.where(np.isfinite(se), se, 0)))
    best, best_ss, fit_best = None, np.inf, None
    for j in range(1, len(ids)):
        fit = np.vstack([np.broadcast_to(np.average(m[:j], axis=0, weights=k[:j]), (j, 3)),
                         np.broadcast_to(np.average(m[j:], axis=0, weights=k[j:]),
                                         (len(ids) - j, 3))])
        ss = float(np.sum(((m - fit) / se) ** 2))
        if ss < best_ss:
            best, best_ss, fit_best = j, ss, fit
    if best is None or fit_best is None:
        return None
    step = fit_best[-1] - fit_best[0]
    se_step = np.sqrt(np.mean(se[:best] ** 2, axis=0) / best
                      + np.mean(se[best:] ** 2, axis=0) / (len(ids) - best))
    if np.max(np.abs(step) / se_step) < STEP_MIN_Z:
        return None
    off = np.abs(m - fit_best)
    if np.any((off > 3.0 * se) & (off > STEP_ONLY_SHARE * np.max(np.abs(step)))):
        return None
    return int(ids[best])


@dataclass(frozen=True)
class VibrationRectification(CatalogueEffect):
    effect_id: str = "vibration_rectification"
    twin_carries: bool = True
    confusers: tuple[str, ...] = ("bias_drift", "session_offset")
    experiment: str = ("record sd_* and take positions with the chamber compressor on and off "
                       "at the same temperature")
    writes_extension: bool = True
    named_by_fit: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        power = vibration_power_g2(ctx)
        out = np.zeros((ctx.n, 3, 3))
        for a in range(3):
            out[:, a, a] = power[:, a]
        return out

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if ctx.sd_g is None:
            return False, "no sd_* columns: the within-window variance is not recorded", \
                self.experiment
        return True, "", self.experiment

    def parameters(self, coef, se, theta, ctx):
        return axis_params("c", "per_g", coef, se, 1.0)

    def sentence(self, params, sd, axes, ctx=None):
        parts = [fmt_pm(params[f"c_{a}_per_g"], sd[f"c_{a}_per_g"], "per g") for a in axes]
        return (f"{'/'.join(axes)} output shifts with the vibration power seen in sd_*: "
                f"c = {', '.join(parts)}")
