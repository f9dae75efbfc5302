"""Soak protocols for gen3 (issue 22): 4–11 plateaus over −40…60 °C in up, down or random
order; a schedule (Table 1, faces, sparse 12 or 18, a random sphere of 30–48); 1–3 visits
per plateau in schedule or shuffled order; a turntable (exact placement) or a hand fixture
re-seated at every capture (a random rotation ≤ 0.5 mrad); the table moves 10–60 s."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.blind.gen3.schedules import HAND_SCHEDULES, SCHEDULE_NAMES, schedule

T_MIN_C, T_MAX_C = -40.0, 60.0
ORDERS = ("up", "down", "random")


@dataclass(frozen=True)
class Protocol:
    setpoints_c: tuple[float, ...]  # in the order they are visited
    order: str
    schedule_name: str
    directions: np.ndarray  # (P, 3) unit gravity directions in the sensor frame
    visits: int
    shuffled: bool  # positions in a fresh random order per pass
    fixture: str  # "table" or "hand"
    place_max_rad: float  # re-seating rotation bound (0 on a table)
    move_s: float  # time the table (or the operator) takes per position


def draw_setpoints(rng: np.random.Generator, order: str) -> tuple[float, ...]:
    """4–11 plateaus spread over −40…60 °C (even spacing, ±2 °C jitter inside)."""
    k = int(rng.integers(4, 12))
    sp = np.linspace(T_MIN_C, T_MAX_C, k)
    sp[1:-1] += rng.uniform(-2.0, 2.0, k - 2)
    sp = np.round(sp, 1)
    if order == "down":
        sp = sp[::-1]
    elif order == "random":
        sp = rng.permutation(sp)
    return tuple(float(v) for v in sp)


def draw_protocol(rng: np.random.Generator) -> Protocol:
    order = str(rng.choice(ORDERS))
    name = str(rng.choice(SCHEDULE_NAMES))
    hand = name in HAND_SCHEDULES and rng.uniform() < 0.4
    return Protocol(
        setpoints_c=draw_setpoints(rng, order), order=order, schedule_name=name,
        directions=schedule(name, rng), visits=int(rng.integers(1, 4)),
        shuffled=bool(rng.uniform() < 0.5), fixture="hand" if hand else "table",
        place_max_rad=float(rng.uniform(0.05e-3, 0.5e-3)) if hand else 0.0,
        move_s=float(rng.uniform(10.0, 60.0)))


def pass_order(rng: np.random.Generator, protocol: Protocol) -> np.ndarray:
    """The positions' order in one pass through the schedule."""
    p = len(protocol.directions)
    return rng.permutation(p) if protocol.shuffled else np.arange(p)
