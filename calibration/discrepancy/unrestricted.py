"""A family candidate's sign-flip replicates from the residual *after* its own columns, with
the stage's signs (the unrestricted wild bootstrap; issue 22).

Why (issue 22, docs/benchmarks.md "Why 2× tilts the oracle separates are missed"): the
stage's wild replicates flip the signs of the residual after the current model alone. An
effect the data hold is in that residual, and the per-reading signs carry it back along the
effect's own columns into every replicate: the family's own null grows heavy, and in the
minimum over families a replicate reaches the data's p (2× tilts, encoder errors and
channel steps missed with no mismatch). Here candidate B's replicates flip the residual
after U *and* B (HC2 by the leverage of [U, B], the same cap, the same left-out readings,
the same plateau offsets), with the same sign draw as every other family's replicate j, so
the minimum over families still compares draws of one sign pattern (independent signs per
candidate made the minimum heavier elsewhere: measured and reverted for the free turn).

With E the stage's replicates, (I − P)(S ⊙ scale + Zb), the candidate's are
E_f = E + (I − P)(S ⊙ d), d = scale_f − scale (the plateau offsets Zb cancel). B ⊥ U, so
BᵀE_f = BᵀE + (R(B ⊙ d))ᵀS and Σ E_f² = Σ E² + 2·colsum(E ⊙ (S ⊙ d)) + Σ d² − ‖Uᵀ(S ⊙ d)‖²,
R the sum of each reading's entries: no (m × B) array per candidate, only (N × k) and
(N × p) sums and one pass over E.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from calibration.discrepancy import stats

# The stage's signs and one (m × B) working copy are kept only within this budget; beyond it
# (a very long recording, where the replicates are cut to their floor for memory) every
# candidate keeps the stage's restricted replicates, as before issue 22's change.
BUDGET_BYTES = 64 * 2**20
# Only candidates whose data log p is below this take the unrestricted replicates (None: every
# candidate): elsewhere the residual after the candidate is the stage's up to the noise along
# its few columns, and a new draw of the replicates' tail only reshuffles the minimum over
# families (measured, docs/benchmarks.md).
DATA_LOG_P_GATE: float | None = None
CANDIDATE_LEVERAGE = True  # HC2 by the leverage of [U, B] (False: of U alone, as the stage's)


@dataclass
class StageSigns:
    """What a candidate's unrestricted replicates need of the stage's wild draw."""

    signs: np.ndarray  # (N, B) ±1, the stage's draw
    row: np.ndarray  # (m,) reading of each entry
    e: np.ndarray  # (m,) the stage's whitened residual (after U)
    h: np.ndarray  # (m,) leverage of U
    scale: np.ndarray  # (m,) the entries the stage's replicates flipped (stats.wild_scale)
    leave_out: tuple[int, ...]
    groups: stats.SharedGroups | None
    U: np.ndarray
    E: np.ndarray  # (m, B) the stage's replicates, projected off U
    EE: np.ndarray  # (B,) Σ E² per replicate
    sum_rows: sp.csr_matrix  # (N, m): each reading's entries summed

    def applies(self, data_log_p: float) -> bool:
        """Whether a candidate with this data log p takes the unrestricted replicates."""
        return DATA_LOG_P_GATE is None or data_log_p < DATA_LOG_P_GATE

    def difference(self, B: np.ndarray) -> np.ndarray:
        """(m,) d = scale_f − scale for the residual after U and B (B ⊥ U, orthonormal)."""
        e_f = self.e - B @ (B.T @ self.e)
        h_f = self.h + np.einsum("ij,ij->i", B, B) if CANDIDATE_LEVERAGE else self.h
        return stats.wild_scale(e_f, h_f, self.row, self.leave_out, self.groups) - self.scale

    def scores(self, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(BᵀE_f, Σ E_f²) of candidate columns B (orthonormal, ⊥ U): its replicates' scores
        and sums of squares, without forming E_f (module docstring)."""
        d = self.difference(B)
        S = self.signs
        BtE = stats.t_matmul(B, self.E) + (self.sum_rows @ (B * d[:, None])).T @ S
        Ud = (self.sum_rows @ (np.asarray(self.U) * d[:, None])).T @ S  # Uᵀ(S ⊙ d)
        cross = np.einsum("nb,nb->b", self.sum_rows @ (self.E * d[:, None]), S)
        EE = self.EE + 2.0 * cross + float(d @ d) - np.einsum("pb,pb->b", Ud, Ud)
        return BtE, EE

    def replicates(self, B: np.ndarray) -> np.ndarray:
        """E_f itself, (m × B): for an effect whose test reads more than the scores
        (``test_stats``: the turntable's across-reference denominator)."""
        W = self.signs[self.row] * self.difference(B)[:, None]
        return self.E + stats.project_out_inplace(self.U, W).astype(self.E.dtype)


def stage_signs(signs: list[np.ndarray], e: np.ndarray, U: np.ndarray, row: np.ndarray,
                E: np.ndarray, leave_out: tuple[int, ...],
                shared: tuple[stats.SharedGroups, np.ndarray, float] | None
                ) -> StageSigns | None:
    """The stage's draw kept for its candidates, or None beyond :data:`BUDGET_BYTES` (or
    without a sign draw: the parametric null)."""
    if not signs or 8 * E.size > BUDGET_BYTES or not isinstance(U, np.ndarray):
        return None
    h = stats.leverage(U)
    groups = shared[0] if shared is not None else None
    m, n = e.size, signs[0].shape[0]
    sum_rows = sp.csr_matrix((np.ones(m), (row, np.arange(m))), shape=(n, m))
    return StageSigns(signs[0], row, e, h, stats.wild_scale(e, h, row, leave_out, groups),
                      leave_out, groups, U, E, stats.sum_sq_columns(E), sum_rows)
