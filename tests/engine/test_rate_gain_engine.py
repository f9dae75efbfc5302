"""The measured temperature_rate gain wired into the engine (issue 12): probes stored,
k re-estimated at every poll, the calibration told k̂, a resume reloading the probes."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from engine_fakes import make_fake_rig
from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Campaign, SoakProbe
from service.engine import rate_gain, store
from service.engine.runner import CampaignRunner
from service.engine.spec import parse_spec

MEASURED = {**SMALL_SPEC, "setpoints_c": [-10.0, 0.0, 10.0, 20.0], "soak_min": 60,
            "rate_gain": "measured", "soak_probe_samples": 200}


class Recorder:
    """The fake core, keeping each provenance it was given."""

    def __init__(self) -> None:
        self.provenances: list[dict] = []

    def __call__(self, columns, provenance):  # type: ignore[no-untyped-def]
        self.provenances.append(provenance)
        return fake_calibrate(columns, provenance)


def probes(sf, cid) -> list[SoakProbe]:  # type: ignore[no-untyped-def]
    with sf() as s:
        return list(s.scalars(select(SoakProbe).where(SoakProbe.campaign_id == cid)
                              .order_by(SoakProbe.t_s)))


def steps_log(sf, cid) -> list[dict]:  # type: ignore[no-untyped-def]
    with sf() as s:
        return list(s.get(Campaign, cid).steps_log)


def test_measured_rate_gain_needs_precise_probes() -> None:
    with pytest.raises(ValueError, match="soak_probe_samples >= 200"):
        parse_spec({"rate_gain": "measured", "soak_probe_samples": 8})
    run = parse_spec({"rate_gain": "measured", "soak_probe_samples": 250,
                      "tempco_ug_per_c": 90.0})
    assert run.rate_gain == "measured"
    assert run.stability.tempco_ug_per_c == 90.0  # the spec's tempco reaches the decision
    assert parse_spec({}).rate_gain == "assumed" and parse_spec({}).soak_probe_samples == 8
    assert parse_spec({"rate_gain": "measured"}).soak_probe_samples == 250


async def test_probes_are_stored_at_home_and_k_reaches_decision_and_fit(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, MEASURED)
    core = Recorder()
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=core)
    assert await asyncio.wait_for(runner.run(), 60) == "completed"
    rows = probes(sf, cid)
    log = steps_log(sf, cid)
    # Every soak's and every ramp's probes at one pose (home: moved there before each ramp),
    # n as specified; a ramp's probes come before its soak's, with the air not yet in band.
    segments: dict[tuple[int, float], list[SoakProbe]] = {}
    for r in rows:
        segments.setdefault((r.step, r.soak_start_t_s), []).append(r)
    ramps = {k: v for k, v in segments.items() if abs(v[0].chamber_c - v[0].setpoint_c) > 0.3}
    soaks = {k: v for k, v in segments.items() if k not in ramps}
    assert len(soaks) == len(MEASURED["setpoints_c"])
    assert sorted(step for step, _ in ramps) == list(range(len(MEASURED["setpoints_c"])))
    for (step, start), ramp in ramps.items():
        soak_start = next(t for s, t in soaks if s == step)
        assert start < soak_start and max(r.t_s for r in ramp) < soak_start
    assert {r.pose for r in rows} == {"0.0,0.0"} and {r.n for r in rows} == {200}
    assert all(r.sensor == "SN-T" for r in rows)
    # The first soak may count on the fit's correction: at most the residual it will leave at
    # worst (the campaign has the soaks to measure k: 50 + 0.1 × (100 + 50)), not the
    # uncorrected prior, less once the first ramp and soak measure k; later soaks a measured,
    # smaller bound (the fake sensor has no rate sensitivity).
    gains = [e["rate_gain_ug_per_c_per_min"] for e in log]
    assert len(MEASURED["setpoints_c"]) >= rate_gain.SOAKS_TO_CORRECT
    assert gains[0] <= 65.0 + 1e-9
    assert all(g < rate_gain.PRIOR_RATE_GAIN_UG_PER_C_PER_MIN for g in gains[2:])
    # The calibration was given the campaign's k̂ and the estimate it came from (every
    # segment with enough probes: the soaks, and the ramps of 6 probes or more).
    (prov,) = core.provenances
    est = prov["rate_gain_estimate"]
    long_ramps = sum(len(v) >= rate_gain.MIN_PROBES_PER_SOAK for v in ramps.values())
    assert est["soaks"] == len(soaks) + long_ramps and long_ramps >= 1
    assert est["probes"] == sum(len(v) for k, v in segments.items()
                                if k in soaks or len(v) >= rate_gain.MIN_PROBES_PER_SOAK) \
        - 2 * long_ramps  # a ramp's first and last probe have no rate
    k_hat = prov["rate_gain_ug_per_c_per_min"]
    assert k_hat is not None and len(k_hat) == 3
    assert np.all(np.abs(k_hat) <= 3 * np.array(est["sd_ug_per_c_per_min"]) + 1.0)


async def test_assumed_rate_gain_keeps_the_lag_and_tells_the_fit_nothing(sf) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf, SMALL_SPEC)
    core = Recorder()
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=core)
    assert await asyncio.wait_for(runner.run(), 60) == "completed"
    assert all(e["rate_gain_ug_per_c_per_min"] is None for e in steps_log(sf, cid))
    assert "rate_gain_ug_per_c_per_min" not in core.provenances[0]
    assert probes(sf, cid)  # probes are measurements: stored whatever the policy


async def test_resume_reloads_the_stored_soaks(sf) -> None:
    cid = add_campaign(sf, MEASURED)
    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    task = asyncio.create_task(
        CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate).run())
    while len(steps_log(sf, cid)) < 3:  # three soaks done: k is measured
        await asyncio.sleep(0.001)
    task.cancel()  # the in-process stand-in for SIGKILL
    with pytest.raises(asyncio.CancelledError):
        await task
    before = {(r.step, r.soak_start_t_s) for r in probes(sf, cid)}
    clock2 = VirtualClock(idle_wall_s=0.0)
    core = Recorder()
    runner = CampaignRunner(sf, cid, make_fake_rig(clock2).devices, clock2, calibrate=core)
    assert await asyncio.wait_for(runner.run(), 60) == "completed"
    after = {(r.step, r.soak_start_t_s) for r in probes(sf, cid)}
    assert before < after  # nothing lost, later soaks added
    # The fit's estimate used the soaks of both processes, not only the second one's.
    assert core.provenances[0]["rate_gain_estimate"]["soaks"] == len(after)
    # The first process's ramps are ramps again after the reload (told apart by the air
    # outside its band at their first probe): as many as the segments the DB holds.
    groups: dict[tuple[int, float], list[SoakProbe]] = {}
    for r in probes(sf, cid):
        groups.setdefault((r.step, r.soak_start_t_s), []).append(r)
    ramps_stored = sum(abs(v[0].chamber_c - v[0].setpoint_c) > 0.3 for v in groups.values())
    (segments,) = runner.rate_book.soaks.values()
    assert ramps_stored >= 3 and sum(s.ramp for s in segments) == ramps_stored
    assert sum(not s.ramp for s in segments) == len(groups) - ramps_stored
    # The first soak after the restart already had an estimate (not the prior).
    log = {e["step"]: e for e in steps_log(sf, cid)}
    resumed = [e for e in log.values() if e["step"] >= 3]
    assert resumed and all(e["rate_gain_ug_per_c_per_min"]
                           < rate_gain.PRIOR_RATE_GAIN_UG_PER_C_PER_MIN for e in resumed)


def test_probe_rows_round_trip_through_the_store(sf) -> None:
    cid = add_campaign(sf)
    row = {"sensor": "SN-T", "step": 1, "soak_start_t_s": 10.0, "pose": "0.0,0.0",
           "t_s": 70.0, "setpoint_c": 10.0, "chamber_c": 10.1, "sensor_c": 12.3,
           "ref_x": 0.0, "ref_y": None, "ref_z": 1.0, "ax": 0.1, "ay": -0.2, "az": 1.0,
           "n": 200}
    store.add_soak_probes(sf, cid, [row, {**row, "t_s": 10.0 + 1.0, "sensor": "SN-U"}])
    store.add_soak_probes(sf, cid, [])
    got = store.soak_probe_rows(sf, cid)
    assert [r["t_s"] for r in got] == [11.0, 70.0]
    assert store.soak_probe_rows(sf, cid, "SN-T") == [row]


def test_corrected_decision_waits_for_the_uncertainty_not_the_gain() -> None:
    typical = rate_gain.RateGain(np.array([95.0, -60.0, 40.0]), np.array([6.0, 3.0, 3.0]),
                                 400, 10)
    # 2σ (12) + 0.1 × (|k̂| + 2σ) (10.7) instead of |k̂| + 2σ (107)
    assert rate_gain.residual_rate_gain_for_decision(typical) == pytest.approx(12.0 + 10.7)
    assert rate_gain.rate_gain_for_decision(typical) == pytest.approx(107.0)
    # k̂ ≈ 0: 2σ + 0.1 × (1 + 2σ), no floor: what is left to wait for is the uncertainty
    none = rate_gain.RateGain(np.array([1.0, 0.0, -1.0]), np.array([4.0, 4.0, 4.0]), 400, 10)
    assert rate_gain.residual_rate_gain_for_decision(none) == pytest.approx(8.0 + 0.9)
    assert rate_gain.correction_gain_ug_per_c_per_min(typical) == pytest.approx([95, -60, 40])
    # Not informative yet: no correction, so the uncorrected rule (the prior) applies.
    weak = rate_gain.RateGain(np.array([5.0, 0.0, 0.0]), np.array([30.0, 3.0, 3.0]), 100, 2)
    assert rate_gain.correction_gain_ug_per_c_per_min(weak) is None
    assert rate_gain.residual_rate_gain_for_decision(weak) == \
        rate_gain.PRIOR_RATE_GAIN_UG_PER_C_PER_MIN
    assert rate_gain.residual_rate_gain_for_decision(None) == \
        rate_gain.PRIOR_RATE_GAIN_UG_PER_C_PER_MIN
    # ... unless the campaign will correct with its final k̂: then the worst residual that
    # correction may leave, the least precise estimate it still uses (2σ = 50) plus a tenth
    # of the larger of the prior and |k̂| (+ 2σ)
    assert rate_gain.residual_rate_gain_for_decision(None, will_correct=True) == \
        pytest.approx(50.0 + 0.1 * (100.0 + 50.0))
    assert rate_gain.residual_rate_gain_for_decision(weak, will_correct=True) == \
        pytest.approx(65.0)
    worse = rate_gain.RateGain(np.array([180.0, 0.0, 0.0]), np.array([40.0, 3.0, 3.0]), 100, 2)
    assert rate_gain.residual_rate_gain_for_decision(worse, will_correct=True) == \
        pytest.approx(50.0 + 0.1 * (180.0 + 50.0))
    # an informative estimate is used as it is, promise or not
    assert rate_gain.residual_rate_gain_for_decision(typical, will_correct=True) == \
        pytest.approx(12.0 + 10.7)


async def test_several_sensors_each_get_their_own_probes_and_gain(sf) -> None:  # type: ignore[no-untyped-def]
    from test_multi_sensor_runner import SERIALS, SPEC, _run, _set_sensor

    spec = {**SPEC, "setpoints_c": [0.0, 10.0, 20.0], "rate_gain": "measured",
            "soak_probe_samples": 200}
    cid = add_campaign(sf, spec)
    _set_sensor(sf, cid, SERIALS[0])
    assert await _run(sf, cid) == "completed"
    rows = probes(sf, cid)
    per_sensor = {s: [r for r in rows if r.sensor == s] for s in SERIALS}
    # every sensor probed at every poll: the same count and times, each its own readings
    assert len({len(v) for v in per_sensor.values()}) == 1 and per_sensor[SERIALS[0]]
    assert len({tuple(round(r.ax, 5) for r in v[:3]) for v in per_sensor.values()}) == 3
    assert {r.pose for r in rows} == {"0.0,0.0,0.0"}
    log = steps_log(sf, cid)
    # three soaks: the first one counts on the fit's correction (65, not the prior's 100)
    assert log[0]["rate_gain_ug_per_c_per_min"] == pytest.approx(65.0)
    assert log[-1]["rate_gain_ug_per_c_per_min"] < rate_gain.PRIOR_RATE_GAIN_UG_PER_C_PER_MIN
