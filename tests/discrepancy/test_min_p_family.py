"""The family test calibrates each family's p on its own replicates before the minimum
(Westfall–Young min-P, stats.min_p_family; issue 22).

The defect it mends (docs/benchmarks.md, the third generator's `outlier` case 5 at 8×): the
outlier family's nominal 10⁻⁷·⁰ was beyond all 400 of its own replicates, but the pose
turns' nominal 10⁻⁶·⁹ was reached by 160 of theirs; the minimum over nominal p was set by
the turns' null and p_family was 0.45.
"""

from __future__ import annotations

import numpy as np

from calibration.discrepancy import stats

B = 400
LN10 = np.log(10.0)


def _nominal_minimum(logp: np.ndarray, logp_null: np.ndarray) -> float:
    """The family test before min-P: the minimum over the families' nominal log p."""
    lmin = logp_null.min(axis=0)
    count = int(np.sum(lmin <= logp.min()))
    p = (1 + count) / (logp_null.shape[1] + 1)
    return min(p, float(np.exp(logp.min())) * len(logp)) if count == 0 else p


def _case5_like(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Family 0 calibrated (uniform p), the recording beyond all its replicates at 10⁻⁷·⁰;
    family 1 anti-conservative, 160 of its 400 replicates at or beyond the recording's
    10⁻⁶·⁹; families 2-4 calibrated, the recording at p 0.3, 0.5, 0.2."""
    rng = np.random.default_rng(seed)
    null = np.log(rng.uniform(size=(5, B)))
    null[1, :160] = -6.9 * LN10 - rng.exponential(3.0, 160)
    null[1, 160:] = -6.9 * LN10 + rng.uniform(0.01, 6.9 * LN10, B - 160)
    data = np.array([-7.0 * LN10, -6.9 * LN10, np.log(0.3), np.log(0.5), np.log(0.2)])
    return data, null


def test_an_anti_conservative_family_no_longer_sets_the_others_threshold():
    data, null = _case5_like()
    assert _nominal_minimum(data, null) > 0.3  # the old test: family 1's null decides
    p, best = stats.min_p_family(data, null)
    assert best == 0  # beyond all of its own replicates
    # Only the item at rank 1 of each other family can tie with it; family 1's is beyond
    # 10⁻⁷·⁰ in nominal p, the calibrated families' are not.
    assert p == 2 / (B + 1)


def test_the_test_is_exact_over_the_items_taken_in_turn():
    """A rank test: with each of the B + 1 items taken as the recording (the others its
    replicates), at most j of them have p_family ≤ j/(B + 1), whatever the families' laws."""
    rng = np.random.default_rng(1)
    n = 200
    items = np.vstack([np.log(rng.uniform(size=n)),          # calibrated
                       4 * np.log(rng.uniform(size=n)),      # anti-conservative
                       0.3 * np.log(rng.uniform(size=n)),    # conservative
                       np.minimum(0.0, rng.normal(0.5, 1.0, n))])  # many ties at log p = 0
    ps = np.array([stats.min_p_family(items[:, i], np.delete(items, i, axis=1))[0]
                   for i in range(n)])
    for j in (1, 2, 5, 10, 20, 50):
        assert np.sum(ps <= j / n + 1e-12) <= j


def test_ties_at_p_one_count_against_the_recording():
    null = np.zeros((3, B))
    null[0, :10] = -1.0
    p, _ = stats.min_p_family(np.zeros(3), null)
    assert p == 1.0


def test_beyond_every_replicate_in_nominal_p_it_is_the_bonferroni_bound():
    rng = np.random.default_rng(2)
    null = np.log(rng.uniform(size=(4, B)))
    data = np.array([np.log(0.5), -30.0, -25.0, np.log(0.1)])
    p, best = stats.min_p_family(data, null)
    assert best == 1
    assert p == _nominal_minimum(data, null) == 4 * np.exp(-30.0)


def test_count_zero_exactly_where_the_nominal_minimum_has_count_zero():
    """At B = 400 and α/2 = 0.0025 only count 0 is significant: there min-P and the nominal
    minimum decide alike and lead with the same family (stats.min_p_family, Resolution)."""
    rng = np.random.default_rng(3)
    seen = 0
    for _ in range(300):
        k = int(rng.integers(2, 8))
        c = rng.uniform(0.3, 4.0, size=(k, 1))  # each family's own (mis)calibration
        null = c * np.log(rng.uniform(size=(k, B)))
        data = c[:, 0] * np.log(rng.uniform(size=k)) * rng.uniform(0.5, 6.0)
        p, best = stats.min_p_family(data, null)
        zero = p <= 1 / (B + 1)
        assert zero == (null.min(axis=0) > data.min()).all()
        if zero:
            seen += 1
            assert best == int(np.argmin(data))
            assert p == _nominal_minimum(data, null)
    assert seen > 10
