"""Position orders per plateau that separate time within a plateau from orientation (issue 10).

With the seed's fixed Table 1 order every position sits at the same time since the step
on every plateau, so "time within the plateau" (a warm-up, a settling die) and
"orientation" (a nonlinearity, orientation history) are the same regressor. Visiting the
positions in a different order on each plateau separates them:

* ``"random"``: an independent seeded permutation per plateau;
* ``"balanced"``: a Williams design (a balanced Latin square): over ``n`` plateaus
  (``2n`` for odd ``n``) every position takes every slot once and follows every other
  position once (first-order carry-over balanced), with the labels permuted by the seed.

This module is the one place those orders are drawn: the engine's
``position_order`` (``calibration/position_order.py``, which also has the least-travel
order) calls :func:`position_order` and visits ``order[step]`` on each step; the
recording carries ``position`` and ``visit`` (the row's index within its step), and the
campaign's spec the scheme and seed, so a diagnosis can rebuild the order.
:func:`time_and_position_confounded` is what the diagnosis checks at the protocol level
(``turntable_geometry`` is withheld on it), :func:`slot_offset_columns` the rival it stands
for: a settling after each move that repeats at each slot of the visiting order
(``slot_settling.py`` judges an input-only name against it; the separability oracle of
``benchmarks/blind/gen2/separable.py`` uses the same columns).
"""

from __future__ import annotations

import numpy as np

SCHEMES = ("fixed", "random", "balanced")


def position_order(n_positions: int, n_steps: int, scheme: str = "balanced",
                   seed: int = 0) -> np.ndarray:
    """(n_steps, n_positions) position indices in visiting order for each plateau."""
    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be one of {', '.join(SCHEMES)}, got {scheme!r}")
    if n_positions < 1 or n_steps < 1:
        raise ValueError(f"need at least one position and one step, got {n_positions}, "
                         f"{n_steps}")
    if scheme == "fixed":
        return np.tile(np.arange(n_positions), (n_steps, 1))
    rng = np.random.default_rng(seed)
    if scheme == "random":
        return np.vstack([rng.permutation(n_positions) for _ in range(n_steps)])
    square = williams_square(n_positions)
    labels = rng.permutation(n_positions)
    rows = labels[square]  # relabel: the balance properties are label-free
    return np.vstack([rows[k % rows.shape[0]] for k in range(n_steps)])


def williams_square(n: int) -> np.ndarray:
    """Williams design: rows are sequences; ``n`` rows (even n) or ``2n`` (odd n).

    First row 0, 1, n−1, 2, n−2, …; row r adds r (mod n). For odd n the mirrored rows
    are appended, which restores carry-over balance.
    """
    first = [0]
    lo, hi = 1, n - 1
    while len(first) < n:
        first.append(lo)
        lo += 1
        if len(first) < n:
            first.append(hi)
            hi -= 1
    base = np.array(first)
    rows = np.vstack([(base + r) % n for r in range(n)])
    return rows if n % 2 == 0 else np.vstack([rows, rows[:, ::-1]])


def time_and_position_confounded(steps: np.ndarray, positions: np.ndarray,
                                 t_s: np.ndarray) -> bool:
    """True when every plateau visits the positions in the same order (Table 1 fixed)."""
    orders = []
    for s in np.unique(steps):
        m = steps == s
        orders.append(tuple(positions[m][np.argsort(t_s[m], kind="stable")].tolist()))
    return len(orders) > 1 and len(set(orders)) == 1


def visit_slots(steps: np.ndarray, positions: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """(N,) index of each reading's visit within its plateau: 0 for the first position
    visited on that plateau, 1 for the next, … (a visit is a run of readings at one position
    in time order, so several readings of one capture share their slot)."""
    steps, positions, t_s = (np.asarray(x) for x in (steps, positions, t_s))
    out = np.zeros(steps.size, np.int64)
    for s in np.unique(steps):
        idx = np.flatnonzero(steps == s)
        idx = idx[np.argsort(t_s[idx], kind="stable")]
        pos = positions[idx]
        out[idx] = np.concatenate([[0], np.cumsum(pos[1:] != pos[:-1])]) if idx.size else []
    return out


def slot_offset_columns(steps: np.ndarray, positions: np.ndarray,
                        t_s: np.ndarray) -> np.ndarray:
    """(N,3,3S): a free offset per axis at each of the S visit slots, the same on every
    plateau — a settling after each move (of the die, of the mount) whose shape depends on
    the move and on the time since the plateau began, both fixed by the slot when the
    order repeats. When every plateau visits the positions in the same order
    (:func:`time_and_position_confounded`) these columns span every function of the
    position, so any per-position effect (a turn of each pose, any function of the specific
    force) lies inside them."""
    slot = visit_slots(steps, positions, t_s)
    n_slot = int(slot.max()) + 1 if slot.size else 0
    out = np.zeros((slot.size, 3, 3 * n_slot))
    for a in range(3):
        out[np.arange(slot.size), a, 3 * slot + a] = 1.0
    return out
