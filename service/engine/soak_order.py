"""The order of a step's positions: least table travel, or a seeded random order.

The seed paper measures its Table 1 positions in table order. Nothing in the
fit depends on the order (every row carries its own reference direction and
die temperature, and the per-step thermal line of
``calibration.temperature_conditioning`` is in time, not in position), so
the order is free to save time: the axes of a rate table move at once, each
with a trapezoidal speed profile, so a move takes as long as its slowest axis
(:func:`move_s`). :func:`order_positions` returns the order with the least
total move time it finds (nearest neighbour from where the table stands, then
2-opt on the open path), or, with ``method="random"``, a permutation drawn
from ``seed`` (for a diagnosis that wants the order decorrelated from time).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# The simulated table's limits (simulators/turntable_sim.py); a rig passes its own.
DEFAULT_SLEW_DEG_PER_S = 20.0
DEFAULT_ACCEL_DEG_PER_S2 = 40.0
METHODS = ("travel", "random", "table")


def axis_move_s(distance_deg: np.ndarray, slew_deg_per_s: float,
                accel_deg_per_s2: float) -> np.ndarray:
    """Time (s) of a rest-to-rest move of ``distance_deg`` with a trapezoidal (or triangular)
    speed profile."""
    d = np.abs(np.asarray(distance_deg, float))
    v, a = slew_deg_per_s, accel_deg_per_s2
    triangular = d <= v * v / a
    return np.where(triangular, 2.0 * np.sqrt(d / a), d / v + v / a)


def move_s(angles_deg: np.ndarray, slew_deg_per_s: float = DEFAULT_SLEW_DEG_PER_S,
           accel_deg_per_s2: float = DEFAULT_ACCEL_DEG_PER_S2) -> np.ndarray:
    """(n, n) move times between table poses ``angles_deg`` (n, axes): the slowest axis."""
    a = np.asarray(angles_deg, float)
    diff = a[:, None, :] - a[None, :, :]
    return axis_move_s(diff, slew_deg_per_s, accel_deg_per_s2).max(axis=2)


def travel_s(angles_deg: np.ndarray, order: Sequence[int], start_deg: Sequence[float] | None = None,
             slew_deg_per_s: float = DEFAULT_SLEW_DEG_PER_S,
             accel_deg_per_s2: float = DEFAULT_ACCEL_DEG_PER_S2) -> float:
    """Total move time (s) of visiting ``angles_deg`` in ``order``, from ``start_deg`` if given."""
    a = np.asarray(angles_deg, float)[list(order)]
    if start_deg is not None:
        a = np.vstack([np.asarray(start_deg, float)[None, :], a])
    steps = axis_move_s(np.diff(a, axis=0), slew_deg_per_s, accel_deg_per_s2)
    return float(steps.max(axis=1).sum()) if steps.size else 0.0


def order_positions(angles_deg: np.ndarray, *, method: str = "travel",
                    start_deg: Sequence[float] | None = None, seed: int | None = None,
                    slew_deg_per_s: float = DEFAULT_SLEW_DEG_PER_S,
                    accel_deg_per_s2: float = DEFAULT_ACCEL_DEG_PER_S2) -> list[int]:
    """An order of the positions (indices into ``angles_deg``, shape (n, axes)).

    ``travel``: least total move time found from ``start_deg`` (default: the
    first position); ``random``: ``np.random.default_rng(seed)`` permutation
    (seed required, so the order is reproducible and recorded); ``table``: as
    given.
    """
    a = np.asarray(angles_deg, float)
    n = a.shape[0]
    if method not in METHODS:
        raise ValueError(f"position order must be one of {METHODS}, got {method!r}")
    if method == "table" or n <= 2:
        return list(range(n))
    if method == "random":
        if seed is None:
            raise ValueError("a random position order needs a seed (so it can be reproduced)")
        return [int(i) for i in np.random.default_rng(seed).permutation(n)]
    cost = move_s(a, slew_deg_per_s, accel_deg_per_s2)
    if start_deg is None:
        first = 0
    else:
        first = int(np.argmin(axis_move_s(a - np.asarray(start_deg, float)[None, :],
                                          slew_deg_per_s, accel_deg_per_s2).max(axis=1)))
    order = _nearest_neighbour(cost, first)
    order = _two_opt(cost, order, None if start_deg is None else
                     axis_move_s(a - np.asarray(start_deg, float)[None, :], slew_deg_per_s,
                                 accel_deg_per_s2).max(axis=1))
    return order


def _nearest_neighbour(cost: np.ndarray, first: int) -> list[int]:
    left = set(range(cost.shape[0])) - {first}
    order = [first]
    while left:
        nxt = min(left, key=lambda j: (cost[order[-1], j], j))
        order.append(nxt)
        left.remove(nxt)
    return order


def _two_opt(cost: np.ndarray, order: list[int], from_start: np.ndarray | None) -> list[int]:
    """Reverse segments of the open path while that shortens it (the start is a fixed
    extra node when ``from_start`` gives the move times from where the table stands)."""

    def length(o: list[int]) -> float:
        total = float(sum(cost[o[i], o[i + 1]] for i in range(len(o) - 1)))
        return total + (float(from_start[o[0]]) if from_start is not None else 0.0)

    best, best_len = list(order), length(order)
    improved = True
    while improved:
        improved = False
        lo = 0 if from_start is not None else 1
        for i in range(lo, len(best) - 1):
            for j in range(i + 1, len(best)):
                cand = best[:i] + best[i:j + 1][::-1] + best[j + 1:]
                cand_len = length(cand)
                if cand_len < best_len - 1e-9:
                    best, best_len, improved = cand, cand_len, True
    return best


def angles_of(refs_g: np.ndarray, n_axes: int = 3) -> np.ndarray:
    """Table angles (n, axes) of unit gravity references, by the rig geometry of
    ``drivers.geometry`` (what the engine commands)."""
    from drivers.geometry import angles_for_reference

    return np.array([angles_for_reference(r, n_axes) for r in np.asarray(refs_g, float)])


__all__ = ["METHODS", "angles_of", "axis_move_s", "move_s", "order_positions", "travel_s"]
