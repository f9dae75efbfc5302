"""Raw-sample recordings: one reading per position, not one per sample (issue 10).

A streamed recording writes every sample of a position's capture as its own row
(``n`` = 1, no ``sd_*``; ~100 Hz, thousands of rows per position). The samples of one
capture are not independent readings: they share the placement (how the box sits on
the table), the vibration and temperature state of that capture, and whatever the
chamber did in those seconds. Treated as independent rows, that common error is
counted once per sample, so any column that follows positions (orientation, lag,
steps) gains a factor ~n in its score, and a null twin was diagnosed ``mismatch``
(docs/benchmarks.md, *Memory, third pass*).

So diagnose works on the capture means, the readings the seed paper's Eq. 1 is
fitted to: mean of the samples, their sample sd and count as ``sd_*`` and ``n`` (the
averaged-reading format). The noise of such a mean is sd/√n *plus* the component the
samples share, which their scatter cannot show; it is estimated from the data by
:func:`calibration.discrepancy.problem.capture_noise`.
"""

from __future__ import annotations

import numpy as np

from calibration.captures import group_means
from calibration.recording import Recording

AXIS_COLUMNS = (("ax", "sd_x"), ("ay", "sd_y"), ("az", "sd_z"))


def is_raw_samples(rec: Recording) -> bool:
    """Several rows per (step, position), each a single sample (``n`` ≤ 1, no ``sd_*``).

    Averaged readings (``n`` > 1 or ``sd_*`` given) are left alone even when a position
    label repeats: each is its own capture with its own scatter. Without a ``position``
    column every row is its own position (Recording.positions), so nothing is grouped.
    """
    if not rec.has("position") or any(rec.has(c) for _, c in AXIS_COLUMNS):
        return False
    n = rec.columns.get("n")
    if n is not None and np.any(np.isfinite(n) & (n > 1)):
        return False
    _, counts = np.unique(_keys(rec), return_counts=True)
    return bool(counts.max(initial=0) > 1)


def _keys(rec: Recording) -> np.ndarray:
    steps, pos = rec.steps().astype(np.int64), rec.positions().astype(np.int64)
    return (steps - steps.min()) * (int(pos.max() - pos.min()) + 1) + (pos - pos.min())


def position_means(rec: Recording) -> Recording:
    """One row per (step, position) capture, in time order: means, sample sd, count.

    Every numeric column is averaged over the capture's finite cells (NaN where none:
    an empty ``chamber_c`` stays empty); ``n`` becomes the number of samples and
    ``sd_*`` their scatter (ddof = 1, two-pass: the µg scatter of ~1 g values is lost
    in Σx² − n·x̄²). A one-sample capture gets an empty ``sd_*`` (the per-step pooled
    median fills it, problem.pooled_sigma_g).
    """
    _, first, inv = np.unique(_keys(rec), return_index=True, return_inverse=True)
    inv = inv.ravel()
    # The step and position of each capture as the samples were grouped (a derived step,
    # from setpoint runs or plateaus, is written out so the means keep it); every other
    # column as the one reader of raw samples aggregates it (calibration.captures).
    cols: dict[str, np.ndarray] = {
        "step": rec.steps()[first].astype(float),
        "position": rec.positions()[first].astype(float),
    }
    cols.update({k: v for k, v in group_means(rec, inv).items()
                 if k not in ("step", "position")})
    order = np.argsort(cols["t_s"], kind="stable")
    out = Recording.from_columns({k: v[order] for k, v in cols.items()}, path=rec.path)
    out.notes.extend(rec.notes)
    return out
