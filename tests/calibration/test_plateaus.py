"""Plateaus only where the die temperature stood still (calibration/plateaus.py)."""

from __future__ import annotations

import numpy as np
import thermal_sim

from calibration.plateaus import TEMPCO_BOUND_UG_PER_C, channel_noise_c, segment_recording
from calibration.recording import Recording
from simulators.ramp_sim import RampProfile, ramp_twin_sensors, simulate_ramp

SHORT = RampProfile(start_c=-20.0, peak_c=40.0, end_c=20.0, rate_c_per_min=1.0)


def _ramp(profile: RampProfile = SHORT, **kw: object):  # noqa: ANN202
    truths, taus = ramp_twin_sensors(1, 3)
    return simulate_ramp(truths, taus, profile, seed=4, **kw)[0]  # type: ignore[arg-type]


def test_a_continuous_ramp_is_never_cut_into_invented_steps() -> None:
    run = _ramp(temp_row_noise_c=0.1, temp_lsb_c=0.11)
    rec = run.recording
    assert np.unique(rec.steps()).size > 10  # what the temperature column alone suggests
    seg = segment_recording(rec)
    assert seg.is_continuous and seg.source == "temperature plateaus"
    assert seg.continuous_rows >= 0.9 * len(rec)
    for s in seg.plateau_ids:  # whatever is kept stood still by the physical criterion
        die = run.die_c[seg.step == s]
        assert np.std(die) * TEMPCO_BOUND_UG_PER_C < 10.0
    assert "continuous row(s)" in seg.notes[-1]


def test_a_mixed_recording_gets_plateaus_for_the_soaks_only() -> None:
    run = _ramp(RampProfile(start_c=-20.0, peak_c=40.0, end_c=20.0, edge_hold_min=40.0))
    seg = segment_recording(run.recording)
    on = seg.step >= 0
    for s in seg.plateau_ids:  # each plateau as one temperature costs < half the noise
        assert np.std(run.die_c[seg.step == s]) * TEMPCO_BOUND_UG_PER_C < 0.5 * seg.row_sigma_ug
    at_edges = (np.abs(run.die_c + 20.0) < 1.0) | (np.abs(run.die_c - 40.0) < 1.0)
    assert np.all(at_edges[on])  # no plateau on the ramps
    start_hold = run.recording.t_s < 40 * 60
    assert on[start_hold].mean() > 0.8  # the soak at the start is a plateau
    mid_ramp = np.abs(run.die_c - 10.0) < 15.0
    assert not on[mid_ramp].any()


def test_a_soak_campaign_stays_steps_and_a_declared_moving_step_does_not() -> None:
    _, rec = thermal_sim.campaign(seed=11, setpoints=(-20.0, 20.0, 60.0))
    seg = segment_recording(rec)
    assert not seg.is_continuous and len(seg.plateau_ids) == 3
    ramp = _ramp(write_setpoint=True).recording  # a ramping setpoint column: one "step" per row
    assert segment_recording(ramp).is_continuous
    cols = dict(rec.columns)
    cols["step"] = np.zeros(len(rec))  # three soaks declared as one step: not a plateau
    seg = segment_recording(Recording.from_columns(cols))
    assert seg.continuous_rows == len(rec)
    assert "not temperature plateaus" in seg.notes[0]


def test_channel_noise_is_measured_through_a_ramp_and_a_quantised_channel() -> None:
    t = np.arange(400) * 15.0
    rng = np.random.default_rng(1)
    temp = -40.0 + t / 60.0 + rng.normal(0, 0.1, t.size)
    assert 0.08 < channel_noise_c(t, temp) < 0.12
    assert 0.08 < channel_noise_c(t, np.round(temp / 0.11) * 0.11) < 0.14
