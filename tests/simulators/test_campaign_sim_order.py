"""The offline simulator interprets the plan's position order: each row's own reference."""

from __future__ import annotations

import numpy as np

from calibration.schedules import table1
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth


def _run(**kw):  # type: ignore[no-untyped-def]
    return simulate_campaign(SensorTruth.adxl355_typical(2), setpoints_c=[-10.0, 10.0, 30.0],
                             soak_min=5.0, samples_per_position=50, seed=3, **kw)


def test_a_random_order_is_visited_recorded_and_each_row_has_its_own_reference() -> None:
    rec = _run(position_order="random", position_order_seed=5)
    step = rec.columns["step"].astype(int)
    pos = rec.columns["position"].astype(int)
    visit = rec.columns["visit"].astype(int)
    refs = table1()
    ref = np.column_stack([rec.columns[k] for k in ("ref_x", "ref_y", "ref_z")])
    assert np.allclose(ref, refs[pos])  # the reference of the position, not of the row index
    for s in range(3):
        m = step == s
        assert sorted(pos[m]) == list(range(24))
        assert list(visit[m]) == list(range(24))  # rows in time order within the step
    orders = [tuple(pos[step == s]) for s in range(3)]
    assert len(set(orders)) == 3 and orders[0] != tuple(range(24))
    # the gravity the sensor saw follows the reference of its position
    raw = np.column_stack([rec.columns[k] for k in ("ax", "ay", "az")])
    assert np.all(np.einsum("ij,ij->i", raw, ref) > 0.95)  # a wrong one: ≤ 0.71


def test_the_schedule_order_stays_the_default_and_writes_no_visit_column() -> None:
    rec = _run()
    assert "visit" not in rec.columns
    assert list(rec.columns["position"].astype(int)) == list(range(24)) * 3
