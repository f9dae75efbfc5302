"""Position order: least table travel, seeded random order, move-time model."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from calibration.position_order import (
    axis_move_s,
    order_positions,
    travel_s,
)
from drivers.geometry import angles_for_references
from service.engine.spec import schedule_refs


def test_move_time_trapezoid_and_triangle() -> None:
    # 20 °/s, 40 °/s²: 10° never reaches slew (triangle 2·√(10/40) = 1 s); 90° = 90/20 + 0.5.
    t = axis_move_s(np.array([0.0, 10.0, -90.0]), 20.0, 40.0)
    assert t == pytest.approx([0.0, 1.0, 5.0])


def test_travel_order_is_a_permutation_and_beats_the_table_order() -> None:
    a = angles_for_references(schedule_refs("table1"))
    order = order_positions(a, start_deg=(0.0, 0.0, 0.0))
    assert sorted(order) == list(range(len(a)))
    assert travel_s(a, order, (0.0, 0.0, 0.0)) < 0.75 * travel_s(a, range(len(a)), (0, 0, 0))


def test_travel_order_is_optimal_on_a_small_case() -> None:
    rng = np.random.default_rng(4)
    a = rng.uniform(-90, 90, (7, 2))
    best = min(travel_s(a, p, (0.0, 0.0)) for p in itertools.permutations(range(7)))
    found = travel_s(a, order_positions(a, start_deg=(0.0, 0.0)), (0.0, 0.0))
    assert found <= 1.05 * best


def test_random_order_is_seeded_and_reproducible() -> None:
    a = angles_for_references(schedule_refs("table1"))
    o1 = order_positions(a, method="random", seed=7)
    assert o1 == order_positions(a, method="random", seed=7)
    assert o1 != order_positions(a, method="random", seed=8)
    assert sorted(o1) == list(range(len(a)))
    with pytest.raises(ValueError, match="seed"):
        order_positions(a, method="random")
    with pytest.raises(ValueError, match="one of"):
        order_positions(a, method="shortest")
    assert order_positions(a, method="table") == list(range(len(a)))


def test_a_campaign_measuring_the_rate_gain_plans_every_step_from_home() -> None:
    # rate_gain "measured" sends the table home at each ramp (campaign_plan.ramp_to): the
    # travel order must then start every step there, not where the last sweep ended.
    from types import SimpleNamespace

    from calibration.campaign_plan import visit_orders

    refs = schedule_refs("table1")
    spec = SimpleNamespace(setpoints_c=[-40.0, -30.0, -20.0], position_order="travel",
                           position_order_seed=None, rate_gain="assumed")
    poses = angles_for_references(refs)
    chained = visit_orders(spec, refs, poses)
    homed = visit_orders(SimpleNamespace(**{**vars(spec), "rate_gain": "measured"}), refs, poses)
    with pytest.raises(ValueError, match="travel position order needs the table pose"):
        visit_orders(spec, refs)  # the plan does not guess a rig's geometry
    from_home = order_positions(angles_for_references(refs), start_deg=(0.0, 0.0, 0.0))
    assert homed == [from_home] * 3
    assert chained[0] == from_home and chained[1] != from_home
