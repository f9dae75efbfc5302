"""Locate the mismatch: residuals by axis, position, step, time (docs/diagnosis.md §3)."""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.discrepancy.context import AXES
from calibration.discrepancy.problem import LinearProblem

ROBUST_Z_FLAG = 4.0


def _group_rms(values: np.ndarray, keys: np.ndarray) -> dict[str, float]:
    names, mean_sq = _group_means(values**2, keys)
    return {
        str(int(k)) if float(k).is_integer() else str(k): float(round(np.sqrt(v), 2))
        for k, v in zip(names, mean_sq, strict=True)
    }


def _group_means(values: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unique keys, mean of ``values`` per key) in one pass (bincount).

    One mask per key was O(rows × keys): with a position index per reading the keys grow
    with the rows, and a 1 M-row recording never left this loop (issue 10).
    """
    names, inverse = np.unique(keys, return_inverse=True)
    inverse = inverse.ravel()
    means = np.bincount(inverse, weights=values, minlength=names.size) / np.bincount(
        inverse, minlength=names.size
    )
    return names, means


def locate_residuals(
    pb: LinearProblem, base_res_g: np.ndarray, final_res_g: np.ndarray, flagged: np.ndarray
) -> dict[str, Any]:
    """RMS of whitened base residuals (noise units: 1 = consistent) by every grouping."""
    ctx = pb.ctx
    z = base_res_g * pb.w  # whitened, entries
    rows = pb.row
    out: dict[str, Any] = {"units": "rms of base-model residual / noise (1 = noise level)"}
    if pb.mode == "reference":
        out["by_axis"] = {
            AXES[a]: float(round(np.sqrt(np.mean(z[pb.axis == a] ** 2)), 2)) for a in range(3)
        }
    out["by_step"] = _group_rms(z, ctx.steps[rows])
    out["by_position"] = _group_rms(z, ctx.positions[rows])
    out["by_direction"] = _group_rms(z, ctx.direction[rows])
    since = ctx.time_since_step_s[rows]
    if np.ptp(since) > 0:
        edges = np.quantile(since, [0.25, 0.5, 0.75])
        out["by_time_since_step_quartile"] = _group_rms(z, np.digitize(since, edges).astype(float))
    elapsed = ctx.t_s[rows]
    edges = np.quantile(elapsed, [0.25, 0.5, 0.75])
    out["by_elapsed_quartile"] = _group_rms(z, np.digitize(elapsed, edges).astype(float))
    # Individual readings: robust z of each reading's whitened residual norm.
    per_row = np.sqrt(np.bincount(rows, z**2, minlength=ctx.n) / np.bincount(rows, minlength=ctx.n))
    med = np.median(per_row)
    mad = 1.4826 * np.median(np.abs(per_row - med)) or 1.0
    rz = (per_row - med) / mad
    out["outlying_rows"] = [int(i) for i in np.flatnonzero(rz > ROBUST_Z_FLAG)[:20]]
    zf = final_res_g * pb.w
    keep = ~flagged[rows]
    out["whitened_rms_before"] = float(round(np.sqrt(np.mean(z**2)), 3))
    out["whitened_rms_after"] = float(round(np.sqrt(np.mean(zf[keep] ** 2)), 3))
    return out


def where_of(pb: LinearProblem, contrib_g: np.ndarray, rows: tuple[int, ...]) -> dict[str, Any]:
    """Steps, positions and time span where a term's fitted contribution is large."""
    ctx = pb.ctx
    if rows:
        idx = np.array(rows, int)
        return {
            "steps": sorted({int(ctx.steps[i]) for i in idx}),
            "positions": sorted({int(ctx.positions[i]) for i in idx}),
            "time_s": [float(ctx.t_s[idx].min()), float(ctx.t_s[idx].max())],
            "rows": [int(i) for i in idx],
        }
    per_row = np.sqrt(np.bincount(pb.row, contrib_g**2, minlength=ctx.n))
    top = float(per_row.max()) if per_row.size else 0.0
    if top <= 0:
        span = [float(ctx.t_s.min()), float(ctx.t_s.max())]
        return {"steps": [], "positions": [], "time_s": span}
    big = per_row >= 0.5 * top

    def groups(keys: np.ndarray) -> list[int]:
        names, means = _group_means(per_row, keys)
        return sorted(int(k) for k in names[means >= 0.5 * means.max()])

    return {
        "steps": groups(ctx.steps),
        "positions": groups(ctx.positions),
        "time_s": [float(ctx.t_s[big].min()), float(ctx.t_s[big].max())],
    }
