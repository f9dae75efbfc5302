"""The forward selection's family test: each family on its own null, then the minimum (issue 22).

Every candidate family gives a Šidák-adjusted log p on the recording and on each of the B
null replicates (``stats.CandidateTest``). The families' nulls differ: the outlier family's
replicates are parametric, the others' are sign flips of the recording's own residual, whose
analytic p runs heavier than nominal on heavy-tailed recordings. Taking the minimum of the raw
p over families let the heaviest null decide for all (an outlier at p = 4·10⁻⁵, beyond all 400
of its own replicates, lost to two replicates of a sign-flip family).

So, in the sense of Westfall & Young's min-p (1993, §2.6):

1. each family's log p is turned into its **own null's tail probability** (``own_null_logq``),
   fitted on the family's B + 1 values (the recording's and the replicates', so the map is
   symmetric in them): the rank (1 + #{b: x_b ≤ x})/(B + 1) above the tail anchor, and
   beyond it a power law in p fitted to the anchor's ranks (``tail_slope``), so the most
   extreme values are not all tied at 1/(B + 1);
2. the **minimum over families** of those calibrated values, on the recording and on each
   replicate;
3. that minimum's tail probability among the replicates' minima, by the same map: the
   family-wise p. It accounts for the families' dependence as the replicates show it.

Why a fitted tail and not ranks alone: at the verdict's α/2 = 1/(B + 1) a rank decides by
whether the recording is beyond every replicate of every family, and each family's most
extreme replicate ties at 1/(B + 1). Beyond the anchor the map assumes the family's log p
falls on a straight line in the log of its rank (a p scaled by a power, as a statistic whose
noise scale is misjudged by a factor gives), with the slope the replicates at 1–5 % show.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.special import digamma

from calibration.discrepancy.stats import CandidateTest

# The tail anchor and the ranks the slope is fitted on: ranks TAIL_FIT_FROM..TAIL_RANKS of
# the B + 1 values (1.25–5 % at B = 400). The most extreme few are left out of the fit, so
# one far value (the recording's own effect, or an isolated replicate) does not set the
# slope it is then judged by.
TAIL_RANKS = 20
TAIL_FIT_FROM = 5
MIN_TAIL_SLOPE = 1.0  # never a tail lighter than a uniform p's


@dataclass(frozen=True)
class FamilyTest:
    """The family test's outcome at one stage."""

    best: CandidateTest  # the family whose own-null tail probability is the smallest
    p_family: float  # family-wise p (tail probability of the minimum among the replicates')
    count: int  # replicates whose minimum is at least as extreme as the recording's
    logq: dict[str, float]  # each group's own-null log tail probability on the recording


def expected_log_order(n: int) -> np.ndarray:
    """E[log U_(i)], i = 1..n, for n uniform values: ψ(i) − ψ(n + 1)."""
    i = np.arange(1, n + 1, dtype=float)
    return digamma(i) - digamma(n + 1.0)


def tail_slope(sorted_x: np.ndarray, anchor: int, fit_from: int) -> float:
    """The tail's log p per log rank, c ≥ 1: least squares through the anchor of the sorted
    values at ranks fit_from..anchor against a uniform's expected log order statistics."""
    n = sorted_x.size
    ell = expected_log_order(n)
    i = np.arange(fit_from - 1, anchor)
    dx = sorted_x[i] - sorted_x[anchor - 1]
    dl = ell[i] - ell[anchor - 1]
    den = float(np.sum(dl * dl))
    c = float(np.sum(dx * dl) / den) if den > 0 else MIN_TAIL_SLOPE
    return max(MIN_TAIL_SLOPE, c) if np.isfinite(c) else MIN_TAIL_SLOPE


def own_null_logq(x: np.ndarray) -> np.ndarray:
    """log tail probability of each of the n = B + 1 values ``x`` (log p; the recording's and
    the replicates') within their own set: rank/n, and beyond the anchor a power-law tail
    (never less extreme than the rank says, so ties at the most extreme rank are broken by
    the tail, not moved above it)."""
    x = np.asarray(x, float)
    n = x.size
    srt = np.sort(x)
    # ties share the largest rank: #{j: x_j ≤ x_i}
    logq = np.log(np.searchsorted(srt, x, side="right") / n)
    tail = _tail_logq(x, srt)
    return logq if tail is None else np.minimum(logq, tail)


def tail_logq(x: np.ndarray) -> np.ndarray:
    """As ``own_null_logq`` but the fitted tail alone beyond the anchor: the family-wise p,
    which must not take the smaller of two readings of one rank."""
    x = np.asarray(x, float)
    srt = np.sort(x)
    logq = np.log(np.searchsorted(srt, x, side="right") / x.size)
    tail = _tail_logq(x, srt)
    if tail is None:
        return logq
    beyond = x < srt[min(TAIL_RANKS, x.size - 1) - 1]
    return np.where(beyond, tail, logq)


def _tail_logq(x: np.ndarray, srt: np.ndarray) -> np.ndarray | None:
    n = x.size
    anchor = min(TAIL_RANKS, n - 1)
    if anchor <= TAIL_FIT_FROM or not np.all(np.isfinite(srt[:anchor])):
        return None
    c = tail_slope(srt, anchor, TAIL_FIT_FROM)
    u = srt[anchor - 1]
    return np.log(anchor / n) + (x - u) / c


def family_test(tests: dict[str, CandidateTest],
                group: Callable[[str], str] | None = None) -> FamilyTest:
    """Each group of families on its own null, the minimum over groups, that minimum on its
    null. ``group``: an effect's group (families whose nulls are drawn alike, compared by
    their raw p within it); None: every family its own group."""
    ids = list(tests)
    key = group or (lambda k: k)
    labels = list(dict.fromkeys(key(k) for k in ids))
    L = np.vstack([np.concatenate(([tests[k].logp_adj], tests[k].logp_adj_null)) for k in ids])
    members = [[j for j, k in enumerate(ids) if key(k) == g] for g in labels]
    G = np.vstack([L[js].min(axis=0) for js in members])
    Q = np.vstack([own_null_logq(row) for row in G])
    m = Q.min(axis=0)
    lead_group = members[int(np.argmin(Q[:, 0]))]
    lead = lead_group[int(np.argmin(L[lead_group, 0]))]
    count = int(np.sum(m[1:] <= m[0]))
    p_family = float(np.exp(tail_logq(m)[0]))
    return FamilyTest(tests[ids[lead]], p_family, count,
                      {g: float(Q[i, 0]) for i, g in enumerate(labels)})
