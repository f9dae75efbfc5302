"""The groups of entries whose noise a plateau shares (issue 22; docs/diagnosis.md §2).

Two components, each one Gaussian offset per group (:class:`stats.SharedGroups`), their
variances fitted to the recording's own residual (:func:`stats.shared_variance`):

* ``plateau x axis``: an offset per plateau and output axis (loading 1 on the whitened
  entries: chamber state, slow vibration, a sub-LSB offset of a quantised channel — what
  moves one axis of every reading of the plateau);
* ``plateau temperature``: one temperature error per plateau through the base model's
  ∂output/∂T (the die's error against the recorded temperature, which moves the three
  axes together in the base's own proportions).

Norm mode has one entry per reading: its first component is one offset per plateau.
"""

from __future__ import annotations

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.problem import LinearProblem

MIN_PLATEAUS = 2  # one plateau has no between-plateau variance to speak of


def plateau_groups(pb: LinearProblem) -> stats.SharedGroups | None:
    """The two shared components of ``pb``'s whitened entries, or None with < 2 plateaus."""
    steps = np.asarray(pb.ctx.steps)
    _, k = np.unique(steps, return_inverse=True)
    n_k = int(k.max()) + 1 if k.size else 0
    if n_k < MIN_PLATEAUS:
        return None
    step_e = k[pb.row]
    axis = np.maximum(pb.axis, 0)
    n_ax = int(axis.max()) + 1
    loads, groups, names = [np.asarray(pb.w, float).copy()], [step_e * n_ax + axis], \
        ["plateau x axis"]
    plateau = [np.repeat(np.arange(n_k), n_ax)]
    dT = np.asarray(pb.ctx.draw_dtemp_g_per_c, float)
    if np.any(dT != 0):
        lt = np.asarray(pb.lift(dT[:, :, None]), float)[:, 0] * pb.w
        if np.any(np.isfinite(lt) & (lt != 0)):
            loads.append(np.where(np.isfinite(lt), lt, 0.0))
            groups.append(step_e)
            names.append("plateau temperature")
            plateau.append(np.arange(n_k))
    return stats.SharedGroups(loads, groups, names, plateau)
