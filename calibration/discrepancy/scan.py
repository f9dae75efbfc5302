"""Localised scan for structure no catalogue term explains (issue 10; docs/diagnosis.md §7).

Replaces "χ²/dof > 2": after the accepted terms, every *local* departure of the base
model is tested, each a small block of free columns confined to one place:

* a **step** and an axis: the SFEM at that plateau differs (columns 1, a_x, a_y, a_z on
  that step's readings — bias and the axis's matrix row; a scale factor that steps at one
  temperature, a cross-axis product at one plateau, a warm-up confined to a step);
* a **position** and an axis: that orientation differs over the campaign (columns 1 and
  the scaled temperature on that position's readings — orientation-history effects, a
  product of two axes at a few positions).

Norm mode has no axes: a block holds the same columns for all three axes, mapped to |g|.
Each block is an F-type score test after projecting out the current model
(:func:`calibration.discrepancy.stats.linear_stats`), with the block's largest residual
entry left out (one reading far out is the outlier test's question); the scan's
statistic is the smallest p over all blocks, and its null is the same minimum on each
parametric-bootstrap replicate (the multiple-comparison cost is paid by the null, not by
a Bonferroni guess). Scale-free (noise from the residual): an optimistic sd/√n cannot
raise it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.context import AXES

MAX_WHERE = 3  # places listed in ``where`` (the strongest, each significant on its own)


@dataclass
class ScanResult:
    p_family: float
    significant: bool
    n_blocks: int
    places: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"test": "localised scan: F score test of every step×axis and position×axis "
                        "block after the model, min-p over blocks against its parametric-"
                        "bootstrap null", "p_value": float(f"{self.p_family:.3g}"),
                "significant": self.significant, "blocks": self.n_blocks,
                "where": self.places}


def scan(pb: Any, U: np.ndarray, e: np.ndarray, E: np.ndarray, alpha: float,
         bounded: stats.BoundedShared | None = None) -> ScanResult:
    """Scan the residual ``e`` (whitened, model projected out; ``E`` its null replicates).

    Blocks with the same (k, dof) share one F law, so the minimum p over them is the p of
    their largest F: the null needs one tail evaluation per group, not per block.
    ``bounded``: an error the data may hold and the null does not (a channel's rounding at
    an LSB its codes admit and the replicates do not draw, within_rounding.py): each
    block's data score is taken net of the most it can put into the block (its reach,
    :class:`stats.BoundedShared`), as the families' tests do with a declared LSB.
    """
    m = e.size
    C = bounded.group_sums(U) if bounded is not None else None
    # Σ E² per replicate without an (m × B) temporary (E is the largest array here).
    ee, EE = float(e @ e), stats.sum_sq_columns(E)
    F: list[float] = []
    kd: list[tuple[int, int]] = []
    kept: list[tuple[str, int, int]] = []
    null_max: dict[tuple[int, int], np.ndarray] = {}
    for label, key, axis, S, Xs in _blocks(pb):
        keep_rows = np.any(Xs != 0, axis=1)  # a block lives on its own (nonzero) entries
        if not keep_rows.all():
            S, Xs = S[keep_rows], Xs[keep_rows]
        if S.size == 0:
            continue
        # Gram of the projected block from its support alone: Z = (I − UUᵀ)X, so
        # ZᵀZ = XᵀX − (UᵀX)ᵀ(UᵀX), and Zᵀe = Xᵀe, ZᵀE = XᵀE because e and E are already
        # orthogonal to U. Exact, and O(|S|) instead of O(m) per block (long recordings
        # have thousands of blocks).
        UX = U[S].T @ Xs
        G = Xs.T @ Xs - UX.T @ UX
        tot = float(np.trace(Xs.T @ Xs))
        if tot <= 0 or 1.0 - float(np.trace(G)) / tot > stats.ABSORBED_MAX:
            continue
        lam, V = np.linalg.eigh(G)
        keep = lam > 1e-12 * max(float(lam.max()), 1e-300)
        k = int(keep.sum())
        if k == 0:
            continue
        W = V[:, keep] / np.sqrt(lam[keep])  # Bᵀ = Wᵀ Zᵀ has orthonormal rows
        dof = max(m - U.shape[1] - k, 1)
        Zs = Xs - U[S] @ UX  # the projected block on its support
        q = float(np.sum((W.T @ _score_without_largest(Xs, Zs, e[S][:, None])[:, 0]) ** 2))
        qn = np.sum((W.T @ _score_without_largest(Xs, Zs, E[S])) ** 2, axis=0)
        q_data = q
        if bounded is not None:  # net of the box's reach (the denominator stays the data's)
            q_data = max(np.sqrt(q) - _block_reach(bounded, C, S, Xs @ W, UX @ W), 0.0) ** 2
        F.append(q_data / k / max((ee - q) / dof, 1e-300))
        fn = qn / k / np.maximum((EE - qn) / dof, 1e-300)
        null_max[(k, dof)] = np.maximum(null_max.get((k, dof), 0.0), fn)
        kd.append((k, dof))
        kept.append((label, key, axis))
    if not F:
        return ScanResult(1.0, False, 0)
    lp_arr = np.empty(len(F))
    for g in set(kd):
        idx = [i for i, x in enumerate(kd) if x == g]
        lp_arr[idx] = stats.f_logsf(np.asarray([F[i] for i in idx]), g[0], g[1])
    null_min = np.min(np.vstack([stats.f_logsf(v, g[0], g[1]) for g, v in null_max.items()]),
                      axis=0)
    best = float(lp_arr.min())
    count = int(np.sum(null_min <= best))
    p_family = (1 + count) / (E.shape[1] + 1)
    if count == 0:  # beyond the bootstrap's resolution: Bonferroni over the blocks
        p_family = min(p_family, float(np.exp(best)) * len(F))
    places = []
    for i in np.argsort(lp_arr)[:MAX_WHERE]:
        # Each listed place must be significant on its own against the scan's null.
        p_i = (1 + int(np.sum(null_min <= lp_arr[i]))) / (E.shape[1] + 1)
        if p_i > alpha and not (i == int(np.argmin(lp_arr)) and p_family <= alpha):
            continue
        label, key, axis = kept[i]
        places.append({label: int(key), "axis": AXES[axis] if axis >= 0 else "norm",
                       "log10_p": round(float(lp_arr[i] / np.log(10)), 1)})
    return ScanResult(float(p_family), bool(p_family <= alpha), len(F), places)


def _block_reach(box: stats.BoundedShared, C: np.ndarray, S: np.ndarray, XW: np.ndarray,
                 UXW: np.ndarray) -> float:
    """The box's reach on a block's projected orthonormal columns B = (I − UUᵀ)X·W, X
    nonzero on its support S only: per group Σ_{i∈S∩g} (XW)_i·z_i − (C·UXW)_g (C the
    box's group sums of U, :meth:`stats.BoundedShared.group_sums`), then
    :meth:`stats.BoundedShared.bound`."""
    g = np.asarray(box.group)
    n_g = C.shape[0]
    M = -(C @ UXW)
    for j in range(XW.shape[1]):
        M[:, j] += np.bincount(g[S], XW[:, j] * box.loading[S], minlength=n_g)
    return box.bound(M)


def _score_without_largest(Xs: np.ndarray, Zs: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(k, B) block scores Zᵀr of each residual column with its largest entry left out.

    Why (issue 22): a block is a *local* departure carried by several readings; one
    reading far out is the outlier test's question, which has the readings' own tail
    (Student-t) as its null. With that one entry in, a position block of 4 readings on a
    sparse protocol was a single-reading test against a Gaussian null, and realistic
    noise (capture means of 20 samples of a vibrating bench) flagged null recordings.
    Leaving entry i out of a residual r ⊥ U: its projection (I − UUᵀ)(r − r_i·δ_i) scores
    Zᵀr − r_i·Z_i = Xᵀr − r_i·Z_i (Z = (I − UUᵀ)X). The same trim is applied to every
    bootstrap replicate, so the null stays exact.
    """
    score = Xs.T @ R
    if R.shape[0] < 2:
        return score
    i = np.argmax(np.abs(R), axis=0)
    return score - Zs[i].T * R[i, np.arange(R.shape[1])]


def _blocks(pb: Any):
    """(label, key, axis, residual entries S, whitened columns on S) of every block.

    Each block is built on its own readings only (``pb.lift_rows``): a dense (m × k) block
    per place made the scan O(rows × places) = O(rows²) in time on long recordings, where
    the places (positions) grow with the rows.
    """
    ctx = pb.ctx
    n = ctx.n
    u = np.column_stack([np.ones(n), ctx.input_g])  # (N,4)
    t = (ctx.temp_c - pb.t_mid_c) / pb.t_half_c
    pos_cols = np.column_stack([np.ones(n), t]) if np.ptp(t) > 0 else np.ones((n, 1))
    per_axis = pb.mode == "reference"
    for label, keys, cols in (("step", ctx.steps, u), ("position", ctx.positions, pos_cols)):
        ids, inverse = np.unique(keys, return_inverse=True)
        if len(ids) < 2 or len(ids) > n // 2:  # one reading per place: an outlier's business
            continue
        members = np.split(np.argsort(inverse, kind="stable"),
                           np.cumsum(np.bincount(inverse, minlength=len(ids)))[:-1])
        kc = cols.shape[1]
        for key, rows in zip(ids, members, strict=True):
            c = cols[rows]
            if per_axis:
                for a in range(3):
                    X = np.zeros((rows.size, 3, kc))
                    X[:, a, :] = c
                    S, Xl = pb.lift_rows(rows, X)
                    on_axis = slice(a, None, 3)  # entries of the other axes are zero
                    yield label, int(key), a, S[on_axis], Xl[on_axis] * pb.w[S[on_axis], None]
            else:
                X = np.zeros((rows.size, 3, 3 * kc))
                for a in range(3):
                    X[:, a, a * kc:(a + 1) * kc] = c
                S, Xl = pb.lift_rows(rows, X)
                yield label, int(key), -1, S, Xl * pb.w[S, None]
