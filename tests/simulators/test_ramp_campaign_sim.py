"""The offline ramp campaign: the engine's ramp plan on the twin's physics, several die lags,
and a recording the calibration fits continuously (simulators/ramp_campaign_sim.py)."""

from __future__ import annotations

import numpy as np

from calibration import gate, sfem
from calibration.continuous import fit_continuous
from calibration.plateaus import segment_recording
from calibration.schedules import get_schedule
from simulators.ramp_campaign_sim import RampCampaignSpec, simulate_ramp_campaign
from simulators.ramp_sim import ramp_twin_sensors

SPEC = RampCampaignSpec(setpoints_c=(0.0, 40.0), ramp_c_per_min=2.0, samples_per_position=50)


def test_each_sensor_is_stamped_with_its_own_die_and_the_shared_air() -> None:
    truths, taus = ramp_twin_sensors(2, seed=3, die_tau_s=(120.0, 600.0))
    camp = simulate_ramp_campaign(truths, taus, SPEC, schedule=get_schedule("six"), seed=2)
    a, b = camp.recordings
    assert len(a) == len(b) and np.array_equal(a.t_s, b.t_s)
    assert not np.array_equal(a.columns["sensor_c"], b.columns["sensor_c"])  # each its own die
    # the slow die lags the fast one on every leg: its largest gap to the air is larger
    gap = np.abs(camp.die_c - camp.air_c[:, None]).max(axis=0)
    assert gap[1] > 2.0 * gap[0]
    # sweeps are step indices of six captures each; every capture has its leg's target
    steps = a.columns["step"]
    assert np.all(np.diff(steps) >= 0) and np.bincount(steps.astype(int)).max() <= 6
    # the setpoint in force: ramping on the legs, held at the two ends while holding
    sp = a.columns["setpoint_c"]
    assert np.unique(sp).size > 20 and np.sum(sp == 0.0) > 6 and np.sum(sp == 40.0) > 6
    assert sp.min() == 0.0 and sp.max() == 40.0


def test_the_recording_is_fitted_continuously_near_the_noise_limit() -> None:
    truths, taus = ramp_twin_sensors(1, seed=5, die_tau_s=(300.0, 300.0))
    camp = simulate_ramp_campaign(truths, taus, SPEC, schedule=get_schedule("table1"), seed=4)
    rec, truth = camp.recordings[0], truths[0]
    seg = segment_recording(rec)
    decided = gate.plan(rec, continuous=seg.is_continuous)
    assert decided.kind == "continuous", decided.reason
    fit = fit_continuous(rec, seg)
    # a static check at 20 °C, the sensor at rest: the model against the true parameters on
    # the same readings (the noise-limited oracle)
    rng = np.random.default_rng(9)
    refs = rng.normal(size=(60, 3))
    refs /= np.linalg.norm(refs, axis=1, keepdims=True)
    die = np.full(60, 20.0)
    raw = truth.ideal_raw_g(refs, die) + rng.normal(0, truth.sample_sd_g() / np.sqrt(200),
                                                   refs.shape)
    cal = fit.model.compensate(raw, die + truth.temp_offset_c)
    oracle = sfem.forward(truth.params_vector_at(die), raw)
    ratio = np.sqrt(np.sum((cal - refs) ** 2) / np.sum((oracle - refs) ** 2))
    assert ratio < 1.25, ratio
