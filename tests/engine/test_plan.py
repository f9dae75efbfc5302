"""One plan, many interpreters: the plan's messages, resume as replay, the dry run, the engine."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from engine_fakes import make_fake_rig
from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate

from drivers.clock import VirtualClock
from service.engine import plan as pl
from service.engine.runner import CampaignRunner
from service.engine.spec import parse_spec, schedule_refs


def messages(spec: dict, done: set[tuple[int, int]] = frozenset()) -> list[pl.Msg]:  # type: ignore[assignment]
    rs = parse_spec(spec)
    out: list[pl.Msg] = []

    def handle(msg: pl.Msg) -> object:
        out.append(msg)
        return ("reading", getattr(msg, "step", None), getattr(msg, "position", None))

    pl.interpret(pl.campaign_plan(rs, schedule_refs(rs.positions), done), handle)
    return out


def test_plan_visits_every_step_and_position_once_then_fits() -> None:
    msgs = messages(SMALL_SPEC)
    saves = [(m.step, m.position) for m in msgs if isinstance(m, pl.Save)]
    assert saves == [(s, p) for s in range(3) for p in range(6)]
    assert [m.setpoint_c for m in msgs if isinstance(m, pl.SetChamber)] == [-10.0, 10.0, 30.0]
    assert isinstance(msgs[0], pl.Configure) and isinstance(msgs[-1], pl.Fit)
    # Every Save carries the reading its Acquire returned, and a checkpoint precedes each move.
    for i, m in enumerate(msgs):
        if isinstance(m, pl.Save):
            assert m.acquisition == ("reading", m.step, m.position)
        if isinstance(m, pl.Move):
            assert isinstance(msgs[i - 1], pl.Checkpoint)
    assert [m.edge for m in msgs if isinstance(m, pl.WaitStable)] == [True, False, True]


def test_resume_is_a_replay_that_skips_what_is_stored() -> None:
    done = {(0, p) for p in range(6)} | {(1, 0), (1, 1)}
    msgs = messages(SMALL_SPEC, done)
    assert [m.step for m in msgs if isinstance(m, pl.SetChamber)] == [1, 2]  # step 0 complete
    assert [m.resumed for m in msgs if isinstance(m, pl.WaitStable)] == [True, False]
    saves = [(m.step, m.position) for m in msgs if isinstance(m, pl.Save)]
    assert saves == [(1, p) for p in range(2, 6)] + [(2, p) for p in range(6)]
    cursor = [m.next_position for m in msgs if isinstance(m, pl.Save)]
    assert cursor[:4] == [3, 4, 5, 6]


def test_dry_run_predicts_duration_and_counts() -> None:
    spec = {**SMALL_SPEC, "settle_s": 5.0, "odr_hz": 62.5}
    dr = pl.dry_run(spec, move_s=12.0, start_c=23.0)
    ramp_s = (33.0 + 20.0 + 20.0) / 2.0 * 60.0  # 23 → −10 → 10 → 30 °C at 2 °C/min
    soak_s = 3 * 30 * 60.0
    positions_s = 3 * 6 * (12.0 + 5.0 + 50 / 62.5)
    assert (dr.n_steps, dr.n_positions, dr.n_saves) == (3, 6, 18)
    assert dr.ramp_s == pytest.approx(ramp_s)
    assert dr.soak_s == pytest.approx(soak_s)
    assert dr.positions_s == pytest.approx(positions_s)
    assert dr.duration_s == pytest.approx(ramp_s + soak_s + positions_s)
    rest = pl.dry_run(spec, done={(0, p) for p in range(6)}, start_c=-10.0)
    assert rest.n_saves == 12 and rest.duration_s < dr.duration_s


def test_dry_run_refuses_an_unparsable_spec() -> None:
    with pytest.raises(ValueError, match="on_max_soak"):
        pl.dry_run({**SMALL_SPEC, "on_max_soak": "explode"})


async def test_engine_executes_exactly_the_plan(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate)
    seen: list[pl.Msg] = []
    runner.subscribe(lambda m, t0, t1: seen.append(m))
    assert await asyncio.wait_for(runner.run(), 30) == "completed"
    expected = messages(SMALL_SPEC)
    assert [type(m) for m in seen] == [type(m) for m in expected]
    assert [(m.step, m.position) for m in seen if isinstance(m, pl.Save)] == [
        (m.step, m.position) for m in expected if isinstance(m, pl.Save)]
    # ETA learnt from the stream: 18 positions timed, three soaks, three ramps.
    assert len(runner.eta.position_times_s) == 18
    assert len(runner.eta.soak_times_s) == 3 and len(runner.eta.ramp_times_s) == 3
    assert np.all(np.asarray(runner.eta.position_times_s) > 0)


def test_offline_simulator_interprets_the_same_plan(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """simulate_campaign has no loop of its own: it executes campaign_plan's messages."""
    from simulators import campaign_sim
    from simulators.truth import SensorTruth

    seen: list[pl.Msg] = []
    real = pl.campaign_plan

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        for m in real(*args, **kwargs):
            seen.append(m)
            yield m

    monkeypatch.setattr(campaign_sim.plan, "campaign_plan", spy)
    rec = campaign_sim.simulate_campaign(SensorTruth.adxl355_typical(0), setpoints_c=[-10.0, 30.0],
                                         schedule=schedule_refs("six"), soak_min=5.0,
                                         samples_per_position=50)
    saves = [(m.step, m.position) for m in seen if isinstance(m, pl.Save)]
    assert saves == [(s, p) for s in range(2) for p in range(6)]
    assert list(rec.columns["step"]) == [s for s, _ in saves]
    assert list(rec.columns["position"]) == [p for _, p in saves]
