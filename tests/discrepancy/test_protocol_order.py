"""Position orders that separate time within a plateau from orientation (issue 10)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.discrepancy.protocol_order import (
    position_order,
    time_and_position_confounded,
    williams_square,
)


@pytest.mark.parametrize("n", [4, 5, 24])
def test_williams_square_is_balanced(n):
    sq = williams_square(n)
    rows = sq.shape[0]
    assert rows == (n if n % 2 == 0 else 2 * n)
    for row in sq:
        assert sorted(row) == list(range(n))  # each row a permutation
    for slot in range(n):  # every position in every slot equally often
        assert np.all(np.bincount(sq[:, slot], minlength=n) == rows // n)
    follows = np.zeros((n, n), int)  # carry-over: each ordered pair once (twice for odd n)
    for row in sq:
        for a, b in zip(row[:-1], row[1:], strict=True):
            follows[a, b] += 1
    off = follows[~np.eye(n, dtype=bool)]
    assert np.all(off == rows // n)


def test_orders_and_the_confounding_check():
    t = np.arange(24 * 3, dtype=float)
    steps = np.repeat(np.arange(3), 24)
    fixed = position_order(24, 3, "fixed").ravel()
    assert time_and_position_confounded(steps, fixed, t)
    for scheme in ("random", "balanced"):
        order = position_order(24, 3, scheme, seed=7)
        assert order.shape == (3, 24)
        assert not time_and_position_confounded(steps, order.ravel(), t)
        assert np.array_equal(order, position_order(24, 3, scheme, seed=7))  # seeded
    with pytest.raises(ValueError, match="scheme"):
        position_order(24, 3, "shuffled")
