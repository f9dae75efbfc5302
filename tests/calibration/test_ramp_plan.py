"""The ramp campaign's plan: legs, holds from the die's lag, sweeps, resume, prediction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import ramp_plan as rp
from calibration.campaign_plan import Fit, ReadChamber, Save, SetChamber, interpret
from calibration.schedules import get_schedule
from calibration.thermal import RANGE_MARGIN_C
from simulators.ramp_campaign_sim import RampCampaignSpec, simulate_ramp_campaign
from simulators.truth import SensorTruth


def test_the_edge_gap_is_the_models_range_margin() -> None:
    assert rp.EDGE_GAP_C == RANGE_MARGIN_C


def test_legs_go_cold_first_then_hot_then_back_holding_only_at_turnarounds() -> None:
    legs = rp.ramp_legs([-40.0, 0.0, 60.0], start_c=23.0, end_c=23.0)
    assert [(g.target_c, g.hold) for g in legs] == [(-40.0, True), (60.0, True), (23.0, False)]
    # started below the range: no turnaround at its low end, the end clamped into the range
    legs = rp.ramp_legs([40.0, 80.0], start_c=23.0, end_c=23.0)
    assert [(g.target_c, g.hold) for g in legs] == [(40.0, False), (80.0, True), (40.0, False)]
    # the end at the hot end: two legs, the cooling direction seen on the first
    legs = rp.ramp_legs([-40.0, 0.0], start_c=23.0, end_c=23.0)
    assert [(g.target_c, g.hold) for g in legs] == [(-40.0, True), (0.0, False)]


def test_legs_done_from_the_stored_setpoints_in_force() -> None:
    legs = rp.ramp_legs([-40.0, 60.0], 23.0, 23.0)
    down = [20.0, 0.0, -30.0]  # the working setpoint ramping to the cold end
    assert rp.legs_done_from([], legs) == 0
    assert rp.legs_done_from(down, legs) == 0
    assert rp.legs_done_from(down + [-40.0] * 5, legs) == 0  # holding at the cold end
    assert rp.legs_done_from(down + [-40.0] * 5 + [-35.0, 10.0], legs) == 1
    assert rp.legs_done_from(down + [-40.0, -20.0, 60.0, 60.0], legs) == 1
    assert rp.legs_done_from(down + [-40.0, 0.0, 60.0, 50.0, 30.0], legs) == 2
    # a capture's setpoint: the ramping working setpoint, the target once arrived
    status = type("S", (), {"process_c": 11.0, "working_setpoint_c": 9.5})()
    assert rp.setpoint_in_force(status, -40.0, arrived=False) == 9.5
    assert rp.setpoint_in_force(status, -40.0, arrived=True) == -40.0
    status.working_setpoint_c = None  # a controller without one: the air
    assert rp.setpoint_in_force(status, -40.0, arrived=False) == 11.0


def test_remaining_approach_of_a_first_order_die_is_its_gap() -> None:
    # a die 10 °C from where it settles, τ = 20 captures: the block estimate is exact
    k = np.arange(60)
    die = 5.0 + 10.0 * np.exp(-k / 20.0)
    gap = die[-1] - 5.0
    assert rp.remaining_approach_c(die, 12) == pytest.approx(gap, rel=0.01)
    assert rp.remaining_approach_c(die[:30], 12) == math.inf  # fewer than three blocks
    # the channel's ±2 °C offset does not change it
    assert rp.remaining_approach_c(die + 2.0, 12) == pytest.approx(gap, rel=0.01)
    # a die standing still within noise has nothing left; one moving away is not settling
    rng = np.random.default_rng(0)
    assert rp.remaining_approach_c(5.0 + rng.normal(0, 0.05, 60), 12) == 0.0
    assert rp.remaining_approach_c(5.0 + 0.1 * k, 12) == math.inf


def test_the_predicted_hold_is_the_first_order_die_s_approach() -> None:
    spec = RampCampaignSpec(setpoints_c=(-40.0, 60.0), ramp_c_per_min=2.0)
    refs = get_schedule("table1")
    for tau_s in (300.0, 900.0):
        pred = rp.predict_ramp(spec, refs, die_tau_s=tau_s, move_s=12.0)
        hold_s = tau_s * math.log(2.0 / 60.0 * tau_s / rp.EDGE_GAP_C)  # τ·ln(r·τ/ε)
        for leg in pred.legs[:2]:
            # a hold ends on a sweep's block boundary: within a sweep of the theory
            assert abs(leg["hold_s"] - hold_s) < 24 * (12.0 + 5.0 + 3.2), (tau_s, leg)
        assert pred.legs[2]["hold_s"] == 0.0
    assert [leg["target_c"] for leg in pred.legs] == [-40.0, 60.0, 23.0]


def _messages(spec: RampCampaignSpec, refs: np.ndarray, **kw) -> list:  # type: ignore[no-untyped-def]
    """The plan's messages on a plant with one 300-s die (the prediction's interpreter)."""
    plant = rp.RampPlant(23.0, [300.0])
    out: list = []

    def handle(msg):  # type: ignore[no-untyped-def]
        out.append(msg)
        if isinstance(msg, SetChamber):
            plant.setpoint_c, plant.rate_c_per_min = msg.setpoint_c, msg.ramp_c_per_min
        elif isinstance(msg, ReadChamber):
            return plant.status()
        plant.advance(15.0 if type(msg).__name__ == "Move" else 0.0)
        if type(msg).__name__ == "Acquire":
            return dict.fromkeys(msg.sensors, rp._Reading(float(plant.die_c[0])))
        return None

    interpret(rp.ramp_plan(spec, refs, **kw), handle)
    return out


def test_sweeps_alternate_direction_and_resume_skips_what_is_stored() -> None:
    spec = RampCampaignSpec(setpoints_c=(20.0, 26.0), ramp_c_per_min=2.0)
    refs = get_schedule("six")
    saves = [m for m in _messages(spec, refs) if isinstance(m, Save)]
    assert all(m.band is False for m in saves)  # no setpoint band: the air is ramping
    by_sweep: dict[int, list[int]] = {}
    for m in saves:
        by_sweep.setdefault(m.step, []).append(m.position)
    assert by_sweep[0] == list(reversed(by_sweep[1]))  # forward, then back
    assert len(by_sweep) >= 4
    # resumed after sweep 0 and two positions of sweep 1, in the second leg
    done = {(0, p) for p in by_sweep[0]} | {(1, p) for p in by_sweep[1][:2]}
    msgs = _messages(spec, refs, done=done, legs_done=1)
    again = [m for m in msgs if isinstance(m, Save)]
    assert again[0].step == 1 and again[0].position == by_sweep[1][2]
    assert not {(m.step, m.position) for m in again} & done
    commands = [m.setpoint_c for m in msgs if isinstance(m, SetChamber)]
    assert commands == [26.0, 23.0]  # the current leg, then the rest
    assert isinstance(msgs[-1], Fit)


def test_the_hold_ends_on_the_slowest_die() -> None:
    truths = [SensorTruth.adxl355_typical(i) for i in range(3)]
    taus = [120.0, 240.0, 480.0]
    spec = RampCampaignSpec(setpoints_c=(10.0, 30.0), ramp_c_per_min=2.0,
                            samples_per_position=20)
    camp = simulate_ramp_campaign(truths, taus, spec, schedule=get_schedule("six"), seed=1)
    # every die, the slowest too, came within the edge gap of both range ends
    assert camp.die_c.min(axis=0).max() <= 10.0 + rp.EDGE_GAP_C
    assert camp.die_c.max(axis=0).min() >= 30.0 - rp.EDGE_GAP_C
    # and no longer than needed: the slowest die's hold, not a fixed one (τ·ln(r·τ/ε) + a sweep)
    hold_s = [leg["end_s"] - leg["start_s"] for leg in camp.legs]
    slow = 480.0 * math.log(2.0 / 60.0 * 480.0 / rp.EDGE_GAP_C)
    ramp_s = 20.0 / 2.0 * 60.0
    assert hold_s[1] < ramp_s + slow + 6 * (12.0 + 5.0 + 0.32) + 300.0


def test_a_resume_after_a_hold_ended_goes_on_with_the_next_leg() -> None:
    """Stopped after the plan ended the cold-end hold and commanded the next leg, but
    before that leg's first capture was stored: the stored dies end the hold, so the resume
    does not hold again. Stopped inside the hold, it holds again (the die may have drifted)."""
    spec = RampCampaignSpec(setpoints_c=(20.0, 26.0), ramp_c_per_min=2.0)
    refs = get_schedule("six")
    msgs = _messages(spec, refs)
    next_leg = next(i for i, m in enumerate(msgs) if isinstance(m, SetChamber) and m.step == 1)
    saves = [m for m in msgs[:next_leg] if isinstance(m, Save)]
    setpoints = [m.setpoint_c for m in saves]
    dies = {"": [m.acquisition[rp.ANY_SENSOR].sensor_c for m in saves]}
    legs = rp.ramp_legs(spec.setpoints_c, 23.0, 23.0)
    assert legs[0].hold and setpoints[-1] == legs[0].target_c  # stopped at the hold's end
    assert rp.legs_done_from(setpoints, legs) == 0  # the setpoints alone: still holding
    assert rp.resumed_legs_done(setpoints, dies, legs, spec, len(refs)) == 1
    # inside the hold: its first captures do not end it
    held = sum(1 for sp in setpoints if sp == legs[0].target_c)
    cut = len(setpoints) - held + 2
    assert rp.resumed_legs_done(setpoints[:cut], {"": dies[""][:cut]}, legs, spec,
                                len(refs)) == 0
    # the resumed plan commands the next leg first and holds no more at the cold end
    again = _messages(spec, refs, done={(m.step, m.position) for m in saves}, legs_done=1)
    assert [m.setpoint_c for m in again if isinstance(m, SetChamber)] == [26.0, 23.0]


def test_a_resumed_prediction_counts_the_stored_sweeps_too() -> None:
    """Progress says "sweep N of about M" with N the stored sweep index: a prediction made
    at a resume counts every sweep, the stored ones included, as the dry run counted them."""
    spec = RampCampaignSpec(setpoints_c=(20.0, 26.0), ramp_c_per_min=2.0)
    refs = get_schedule("six")
    stored = {(m.step, m.position) for m in _messages(spec, refs) if isinstance(m, Save)}
    last_sweep = max(s for s, _ in stored)
    fresh = rp.predict_ramp(spec, refs, start_c=23.0, end_c=23.0)
    assert fresh.n_sweeps >= 3
    # resumed on the last leg with the chamber at its end: nothing left to measure
    rest = rp.predict_ramp(spec, refs, start_c=23.0, end_c=23.0, done=stored, legs_done=2)
    assert rest.n_saves == 0
    assert rest.n_sweeps == last_sweep + 1
