"""The order of a step's positions: least table travel, a seeded random or a balanced order.

The seed paper measures its Table 1 positions in table order. Nothing in the
fit depends on the order (every row carries its own reference direction and
die temperature, and the per-step thermal line of
``calibration.temperature_conditioning`` is in time, not in position), so
the order is free to save time: the axes of a rate table move at once, each
with a trapezoidal speed profile, so a move takes as long as its slowest axis
(:func:`move_s`). :func:`order_positions` returns the order with the least
total move time it finds (nearest neighbour from where the table stands, then
2-opt on the open path), or, with ``method="random"`` / ``"balanced"``, the
seeded per-plateau orders of :mod:`calibration.discrepancy.protocol_order`
(the one place those orders are drawn; for a diagnosis that wants the order
decorrelated from time). :func:`step_orders` gives the order of every step of
a campaign, which the plan (:mod:`calibration.campaign_plan`) visits.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from calibration.discrepancy.protocol_order import position_order

# The simulated table's limits (simulators/turntable_sim.py); a rig passes its own.
DEFAULT_SLEW_DEG_PER_S = 20.0
DEFAULT_ACCEL_DEG_PER_S2 = 40.0
METHODS = ("travel", "random", "balanced", "table")
# position_order's method name → protocol_order's scheme name (the seeded orders live there).
_SCHEME = {"random": "random", "balanced": "balanced", "table": "fixed"}


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
                    step: int = 0,
                    slew_deg_per_s: float = DEFAULT_SLEW_DEG_PER_S,
                    accel_deg_per_s2: float = DEFAULT_ACCEL_DEG_PER_S2) -> list[int]:
    """An order of the positions (indices into ``angles_deg``, shape (n, axes)).

    ``travel``: least total move time found from ``start_deg`` (default: the
    first position); ``random``: the seeded permutation of plateau ``step``
    (seed required, so the order is reproducible and recorded); ``balanced``:
    row ``step`` of the seeded Williams design (seed default 0); ``table``: as
    given. ``random`` and ``balanced`` are
    :func:`calibration.discrepancy.protocol_order.position_order`'s.
    """
    a = np.asarray(angles_deg, float)
    n = a.shape[0]
    if method not in METHODS:
        raise ValueError(f"position order must be one of {METHODS}, got {method!r}")
    if method == "random" and seed is None:
        raise ValueError("a random position order needs a seed (so it can be reproduced)")
    if method != "travel":
        if n < 1:
            return []
        rows = position_order(n, step + 1, _SCHEME[method], 0 if seed is None else int(seed))
        return [int(i) for i in rows[step]]
    if n <= 2:
        return list(range(n))
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
    extra node when ``from_start`` gives the move times from where the table stands).

    A reversal of ``best[i..j]`` changes only the two edges at its ends (the move
    times are symmetric), so each candidate costs O(1): the first improving reversal
    in (i, j) order is taken, as a full re-sum would take it.
    """
    best = list(order)
    n = len(best)
    improved = True
    while improved:
        improved = False
        lo = 0 if from_start is not None else 1
        for i in range(lo, n - 1):
            for j in range(i + 1, n):
                a, b = best[i], best[j]
                if i == 0:
                    before = after = 0.0
                    if from_start is not None:
                        before, after = float(from_start[a]), float(from_start[b])
                else:
                    p = best[i - 1]
                    before, after = float(cost[p, a]), float(cost[p, b])
                if j + 1 < n:
                    q = best[j + 1]
                    before += float(cost[b, q])
                    after += float(cost[a, q])
                if after - before < -1e-9:
                    best[i:j + 1] = best[i:j + 1][::-1]
                    improved = True
    return best


def step_orders(angles_deg: np.ndarray, n_steps: int, method: str = "travel",
                seed: int | None = None, start_deg: Sequence[float] | None = None,
                slew_deg_per_s: float = DEFAULT_SLEW_DEG_PER_S,
                accel_deg_per_s2: float = DEFAULT_ACCEL_DEG_PER_S2,
                home_each_step: bool = False) -> list[list[int]]:
    """The visiting order of every step of a campaign: ``n_steps`` lists of indices.

    ``travel``: step 0 from ``start_deg`` (default home, every axis at 0°), each
    later step from the last pose of the step before, so a whole sweep and the
    step after it are chained; with ``home_each_step`` every step from
    ``start_deg`` (the engine parks the table at home before each ramp when it
    measures the rate gain: its soak probes must share one pose). Deterministic:
    the same arguments give the same orders, so a resumed campaign visits what is
    missing in the order it had (independent of which positions are stored).
    Cached: the plan is replayed by every dry run.
    """
    a = np.asarray(angles_deg, float)
    home = tuple(0.0 for _ in range(a.shape[1])) if start_deg is None else tuple(start_deg)
    return [list(o) for o in _step_orders(a.tobytes(), a.shape, int(n_steps), method,
                                          None if seed is None else int(seed),
                                          tuple(float(v) for v in home),
                                          float(slew_deg_per_s), float(accel_deg_per_s2),
                                          bool(home_each_step))]


@functools.lru_cache(maxsize=64)
def _step_orders(raw: bytes, shape: tuple[int, ...], n_steps: int, method: str,
                 seed: int | None, start: tuple[float, ...], slew: float,
                 accel: float, home_each_step: bool) -> tuple[tuple[int, ...], ...]:
    a = np.frombuffer(raw, float).reshape(shape)
    out: list[tuple[int, ...]] = []
    here: Sequence[float] = start
    for step in range(n_steps):
        order = order_positions(a, method=method, start_deg=here, seed=seed, step=step,
                                slew_deg_per_s=slew, accel_deg_per_s2=accel)
        out.append(tuple(order))
        if order and not home_each_step:
            here = tuple(a[order[-1]])
    return tuple(out)


__all__ = ["METHODS", "axis_move_s", "move_s", "order_positions", "step_orders",
           "travel_s"]
