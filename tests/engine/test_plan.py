"""One plan, many interpreters: the plan's messages, resume as replay, the dry run, the engine."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from engine_fakes import make_fake_rig
from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate
from sqlalchemy import select

from calibration import campaign_plan as pl
from drivers.clock import VirtualClock
from drivers.geometry import angles_for_references
from service.db.models import Measurement
from service.dry_run import dry_run
from service.engine.runner import CampaignRunner
from service.engine.spec import parse_spec, schedule_refs

TABLE_ORDER = {**SMALL_SPEC, "position_order": "table"}


def messages(spec: dict, done: set[tuple[int, int]] = frozenset(),  # type: ignore[assignment]
             sensors: tuple[str, ...] = ()) -> list[pl.Msg]:
    rs = parse_spec(spec)
    out: list[pl.Msg] = []

    def handle(msg: pl.Msg) -> object:
        out.append(msg)
        return ("reading", getattr(msg, "step", None), getattr(msg, "position", None))

    refs = schedule_refs(rs.positions)
    pl.interpret(pl.campaign_plan(rs, refs, done, sensors, angles_for_references(refs)),
                 handle)
    return out


def saves_of(msgs: list[pl.Msg]) -> list[tuple[int, int]]:
    return [(m.step, m.position) for m in msgs if isinstance(m, pl.Save)]


def test_plan_visits_every_step_and_position_once_then_fits() -> None:
    msgs = messages(TABLE_ORDER)
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
    msgs = messages(TABLE_ORDER, done)
    assert [m.step for m in msgs if isinstance(m, pl.SetChamber)] == [1, 2]  # step 0 complete
    assert [m.resumed for m in msgs if isinstance(m, pl.WaitStable)] == [True, False]
    saves = [(m.step, m.position) for m in msgs if isinstance(m, pl.Save)]
    assert saves == [(1, p) for p in range(2, 6)] + [(2, p) for p in range(6)]
    cursor = [m.next_position for m in msgs if isinstance(m, pl.Save)]
    assert cursor[:4] == [3, 4, 5, 6]


def test_dry_run_predicts_duration_and_counts() -> None:
    spec = {**SMALL_SPEC, "settle_s": 5.0, "odr_hz": 62.5}
    dr = dry_run(spec, move_s=12.0, start_c=23.0)
    ramp_s = (33.0 + 20.0 + 20.0) / 2.0 * 60.0  # 23 → −10 → 10 → 30 °C at 2 °C/min
    soak_s = 3 * 30 * 60.0
    positions_s = 3 * 6 * (12.0 + 5.0 + 50 / 62.5)
    assert (dr.n_steps, dr.n_positions, dr.n_saves) == (3, 6, 18)
    assert dr.ramp_s == pytest.approx(ramp_s)
    assert dr.soak_s == pytest.approx(soak_s)
    assert dr.positions_s == pytest.approx(positions_s)
    assert dr.duration_s == pytest.approx(ramp_s + soak_s + positions_s)
    rest = dry_run(spec, done={(0, p) for p in range(6)}, start_c=-10.0)
    assert rest.n_saves == 12 and rest.duration_s < dr.duration_s


def test_dry_run_refuses_an_unparsable_spec() -> None:
    with pytest.raises(ValueError, match="on_max_soak"):
        dry_run({**SMALL_SPEC, "on_max_soak": "explode"})


async def test_engine_executes_exactly_the_plan(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate)
    seen: list[pl.Msg] = []
    runner.subscribe(lambda m, t0, t1: seen.append(m))
    assert await asyncio.wait_for(runner.run(), 30) == "completed"
    rs = parse_spec(SMALL_SPEC)
    refs = schedule_refs(rs.positions)
    poses = np.array([rig.devices.angles_for(r) for r in refs])  # this rig's geometry
    expected = []
    pl.interpret(pl.campaign_plan(rs, refs, angles_deg=poses),
                 lambda m: expected.append(m))  # type: ignore[func-returns-value]
    # The composite waits are expanded by the engine into their stubs' polls
    # (wait_for_chamber, soak_until_stable), announced before the composite itself:
    # Poll (Checkpoint Wait Poll)* — take them out and the rest is the plan, message by message.
    top: list[pl.Msg] = []
    expansions: list[list[type]] = []
    current: list[type] | None = None
    for m in seen:
        if current is None and isinstance(m, pl.PollChamber | pl.PollSoak):
            current = []
        if current is not None and not isinstance(m, pl.WaitChamber | pl.WaitStable):
            current.append(type(m))
            continue
        if current is not None:
            expansions.append(current)
            current = None
        top.append(m)
    assert [type(m) for m in top] == [type(m) for m in expected]
    assert [(m.step, m.position) for m in top if isinstance(m, pl.Save)] == [
        (m.step, m.position) for m in expected if isinstance(m, pl.Save)]
    assert len(expansions) == 6  # three ramps, three soaks
    for run in expansions:
        assert run[0] in (pl.PollChamber, pl.PollSoak)
        assert run[1:] == [pl.Checkpoint, pl.Wait, run[0]] * ((len(run) - 1) // 3)
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


def test_the_default_travel_order_visits_each_position_once_and_moves_less() -> None:
    from calibration.position_order import travel_s

    spec = {**SMALL_SPEC, "positions": "table1"}
    saves = saves_of(messages(spec))
    table = saves_of(messages({**spec, "position_order": "table"}))
    assert sorted(saves) == sorted(table)
    poses = angles_for_references(schedule_refs("table1"))
    home = (0.0, 0.0, 0.0)
    chained = [p for _, p in saves]  # the whole campaign's moves, step after step
    assert travel_s(poses, chained, home) < 0.7 * travel_s(poses, [p for _, p in table], home)


def test_a_resumed_step_visits_its_missing_positions_in_the_order_it_had() -> None:
    for order in ({"position_order": "travel"},
                  {"position_order": "random", "position_order_seed": 3},
                  {"position_order": "balanced"}):
        spec = {**SMALL_SPEC, "positions": "table1", **order}
        full = saves_of(messages(spec))
        step1 = [p for s, p in full if s == 1]
        done = {(0, p) for p in range(24)} | {(1, p) for p in step1[:5]}
        rest = saves_of(messages(spec, done))
        assert rest[:19] == [(1, p) for p in step1[5:]], order
        assert rest[19:] == [sp for sp in full if sp[0] == 2], order


def test_random_and_balanced_orders_differ_per_plateau_and_come_from_protocol_order() -> None:
    from calibration.discrepancy.protocol_order import position_order

    for name, seed in (("random", 11), ("balanced", 4)):
        spec = {**SMALL_SPEC, "position_order": name, "position_order_seed": seed}
        by_step = [[p for s, p in saves_of(messages(spec)) if s == k] for k in range(3)]
        assert by_step == position_order(6, 3, name, seed).tolist()
        assert len({tuple(o) for o in by_step}) == 3  # time within the plateau ≠ position
    other = {**SMALL_SPEC, "position_order": "random", "position_order_seed": 12}
    assert saves_of(messages(other)) != saves_of(
        messages({**other, "position_order_seed": 11}))


def test_a_random_order_without_a_seed_is_refused_naming_the_seed() -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="position_order_seed"):
        parse_spec({**SMALL_SPEC, "position_order": "random"})
    with pytest.raises(ValidationError, match="position_order"):
        parse_spec({**SMALL_SPEC, "position_order": "shortest"})
    with pytest.raises(ValidationError, match="position_order_seed"):
        parse_spec({**SMALL_SPEC, "position_order": "random", "position_order_seed": -1})


def test_several_sensors_are_read_by_one_acquire_per_position() -> None:
    serials = ("SN-1", "SN-2", "SN-3")
    msgs = messages(SMALL_SPEC, sensors=serials)
    acquires = [m for m in msgs if isinstance(m, pl.Acquire)]
    assert len(acquires) == 18 and all(m.sensors == serials for m in acquires)
    assert all(m.sensors == serials for m in msgs if isinstance(m, pl.Save))


def test_dry_run_counts_the_order_s_table_travel_and_one_capture_for_all_sensors() -> None:
    spec = {**SMALL_SPEC, "positions": "table1"}
    travel = dry_run(spec, move_s=None)
    table = dry_run({**spec, "position_order": "table"}, move_s=None)
    assert travel.positions_s < table.positions_s - 3 * 20.0  # ≥ 20 s of moves saved per step
    eight = dry_run({**spec, "sensors": [f"SN-{i}" for i in range(8)]}, move_s=None)
    assert eight.positions_s == pytest.approx(travel.positions_s)  # read concurrently
    assert eight.n_saves == travel.n_saves


def test_dry_run_starts_each_step_s_travel_at_home_where_the_plan_sends_the_table_there() -> None:
    # A campaign measuring the rate gain homes the table at each ramp (the plan's Home):
    # every step's sweep then starts at home and costs the same travel.
    spec = {**SMALL_SPEC, "rate_gain": "measured", "setpoints_c": [-10.0, 10.0, 30.0]}
    steps_s = [s["positions_s"] for s in dry_run(spec, move_s=None).steps]
    assert steps_s == pytest.approx([steps_s[0]] * 3)
    assumed = [s["positions_s"] for s in dry_run({**spec, "rate_gain": "assumed"},
                                                 move_s=None).steps]
    assert assumed[0] == pytest.approx(steps_s[0])  # the first step starts at home anyway


def test_wait_stable_says_how_many_steps_share_its_position_order() -> None:
    """A campaign measuring the rate gain starts every step from home, so every step of the
    travel order is the same permutation; chained from the step before, they differ."""
    from calibration.campaign_plan import WaitStable, campaign_plan
    from calibration.campaign_spec import CampaignSpec
    from calibration.schedules import table1

    sp = (-40.0, -30.0, -20.0, -10.0, 0.0)
    home = CampaignSpec(setpoints_c=sp, position_order="travel", rate_gain="measured")
    poses = angles_for_references(table1())
    waits = [m for m in campaign_plan(home, table1(), angles_deg=poses)
             if isinstance(m, WaitStable)]
    assert [w.order_repeats for w in waits] == [len(sp)] * len(sp)
    seeded = CampaignSpec(setpoints_c=sp, position_order="random", position_order_seed=1)
    waits = [m for m in campaign_plan(seeded, table1()) if isinstance(m, WaitStable)]
    assert [w.order_repeats for w in waits] == [1] * len(sp)


def test_a_retake_measures_the_position_again_from_the_move() -> None:
    # The interpreter answers a Save with RETAKE (its capture read another pose): the plan
    # moves, settles, acquires and saves that position again; nothing else changes.
    rs = parse_spec(TABLE_ORDER)
    refs = schedule_refs(rs.positions)
    out: list[pl.Msg] = []
    retaken: set[tuple[int, int]] = set()

    def handle(msg: pl.Msg) -> object:
        out.append(msg)
        if isinstance(msg, pl.Save) and (msg.step, msg.position) == (1, 3) \
                and (1, 3) not in retaken:
            retaken.add((1, 3))
            return pl.RETAKE
        return None

    pl.interpret(pl.campaign_plan(rs, refs), handle)
    assert saves_of(out).count((1, 3)) == 2
    assert sorted(set(saves_of(out))) == [(s, p) for s in range(3) for p in range(6)]
    first = saves_of(out).index((1, 3))
    again = out[[i for i, m in enumerate(out) if isinstance(m, pl.Save)][first] + 1:]
    assert [type(m) for m in again[:5]] == [pl.Checkpoint, pl.Move, pl.Settle, pl.Acquire,
                                            pl.Save]
    assert again[1].position == 3


def test_the_ramp_commands_then_waits_and_goes_home_first_when_the_rate_gain_is_measured(
) -> None:
    plain = [type(m) for m in pl.ramp_to(0, 20.0, 1.0)]
    assert plain == [pl.SetChamber, pl.WaitChamber]
    measured = messages({**TABLE_ORDER, "rate_gain": "measured"})
    i = next(i for i, m in enumerate(measured) if isinstance(m, pl.SetChamber))
    assert [type(m) for m in measured[i:i + 3]] == [pl.SetChamber, pl.Home, pl.WaitChamber]


async def test_a_plan_whose_chamber_never_stops_saves_without_the_band(sf) -> None:  # type: ignore[no-untyped-def]
    # The verbs a ramp campaign builds on: SetChamber only commands, ReadChamber tells where
    # the air is, and a Save with band=False stores readings taken while the air moves
    # (a Save with the band armed would hold instead: the air is far from the setpoint).
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, {**SMALL_SPEC, "setpoints_c": [40.0]})
    airs: list[float] = []

    def ramp_plan(spec, refs, done, *, sensors, angles_deg):  # type: ignore[no-untyped-def]
        yield pl.Configure(float(spec.range_g), float(spec.odr_hz))
        yield pl.SetChamber(0, 40.0, 0.5)
        for pos in range(refs.shape[0]):
            if (0, pos) in done:
                continue
            airs.append((yield pl.ReadChamber()).process_c)
            ref = tuple(float(v) for v in refs[pos])
            yield from pl.measure_position(0, pos, 40.0, ref, pos + 1, tuple(sensors),
                                           int(spec.samples_per_position), 0.0, band=False)

    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate,
                            plan=ramp_plan)
    assert await asyncio.wait_for(runner.run(), 30) == "completed"
    with sf() as s:
        rows = s.execute(select(Measurement.position, Measurement.chamber_c)
                         .where(Measurement.campaign_id == cid)).all()
    assert sorted(p for p, _ in rows) == list(range(6))
    assert max(c for _, c in rows) < 40.0 - 2.0  # every reading far outside a 2 °C band
    assert airs == sorted(airs) and airs[-1] > airs[0]  # the air kept rising meanwhile
    assert not runner.suspension_log
