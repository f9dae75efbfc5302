"""A thermal/time-family name is not given where a jump of the output at a temperature fits
as well (calibration/discrepancy/temperature_jump.py, issue 22).

A bias that jumps where the die crosses T* (outside the catalogue) was named a power cycle
on one-way staircases (the plateaus after the "cycle" are exactly the hot ones) and a
rectified vibration where the compressor runs on the cold plateaus only. The true catalogue
effects of those shapes keep their names where the data tell them apart: a power cycle at
the turn of an up-down campaign (both legs cross T*), vibration that changes on warm
plateaus as well.

Recordings from the second generator with synthetic noise pools (the benchmark's pools come
from real recordings outside the repository).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2 import unseen_effects as ux
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.discrepancy.temperature_jump import jump_column, thresholds_c
from calibration.recording import Recording

VIB_G = 0.4e-3  # per-sample rms of the bench's vibration on a vibrating plateau
CATALOGUE_NAMES = {"session_offset", "vibration_rectification", "thermal_hysteresis",
                   "bias_drift", "temperature_rate"}


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _record(seed: int, kind: str, eid: str | None, m: float, vib: str = "cold",
            **pat) -> Recording:
    rng = np.random.default_rng(700 + seed)
    pr = protocol.draw_protocol(rng, kind=kind, schedule="dense24", columns=("sensor_c",),
                                soak_min=20.0)
    levels = {"cold": [VIB_G if t < 5 else 0.0 for t in pr.setpoints_c],
              "none": [0.0] * len(pr.setpoints_c),
              # a vibration power that changes on warm plateaus too (a duty cycle)
              "varied": [VIB_G if t < 5 else (0.6 * VIB_G if i % 2 else 0.0)
                         for i, t in enumerate(pr.setpoints_c)]}[vib]
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "irregular": False, "vib_sd_g": tuple(levels),
                               "power_cycle_at": (len(pr.setpoints_c) // 2 if kind == "updown"
                                                  else None)})
    sensor = draw_sensor(rng)
    p = {**fx.pattern(rng, len(pr.setpoints_c), 10), **ux.unseen_pattern(seed, pr.setpoints_c),
         **pat}
    return Recording.from_columns(sim.record(pr, sensor, _pools(), eid, m, p, seed))


def _names(d) -> list[str]:
    return [f.effect for f in d.findings]


def test_thresholds_lie_between_distinct_plateau_temperatures():
    assert thresholds_c({0: -20.0, 1: 0.0, 2: 0.2, 3: 40.0}) == [-10.0, 20.0]
    assert thresholds_c({0: 25.0}) == []


def test_a_jump_at_a_temperature_on_a_one_way_staircase_is_not_called_a_power_cycle():
    for seed in (1, 2):
        rec = _record(seed, "oneway", "thermal_threshold", 60.0, vib="none")
        d = diagnose(rec, seed=seed, n_null=200)
        assert d.findings, "the jump is far above the noise: it must be found"
        assert not CATALOGUE_NAMES & set(_names(d)), _names(d)
        top = d.findings[0]
        assert top.effect == "not_identifiable"
        cands = top.where["candidates"]
        assert any("jump of the output" in c for c in cands), cands


def test_a_power_cycle_at_the_turn_of_an_up_down_campaign_keeps_its_name():
    rec = _record(3, "updown", "session_offset", 60.0, vib="none")
    d = diagnose(rec, seed=3, n_null=200)
    assert _names(d)[:1] == ["session_offset"], _names(d)


def test_a_jump_at_a_temperature_where_only_the_cold_plateaus_vibrate_is_not_vibration():
    # T* between the cold (vibrating) plateaus and the warm ones
    rng = np.random.default_rng(704)
    pr = protocol.draw_protocol(rng, kind="updown", schedule="dense24", columns=("sensor_c",),
                                soak_min=20.0)
    sp = np.unique(pr.setpoints_c)
    t_star = float((sp[sp < 5].max() + sp[sp >= 5].min()) / 2)
    rec = _record(4, "updown", "thermal_threshold", 60.0, vib="cold", threshold_c=t_star)
    d = diagnose(rec, seed=4, n_null=200)
    assert d.findings
    assert "vibration_rectification" not in _names(d), _names(d)


def test_vibration_that_also_changes_on_warm_plateaus_keeps_its_name():
    rec = _record(5, "updown", "vibration_rectification", 600.0, vib="varied")  # 96 µg cold
    d = diagnose(rec, seed=5, n_null=200)
    assert _names(d)[:1] == ["vibration_rectification"], _names(d)


def test_the_jump_column_marks_the_plateaus_above_the_threshold():
    ctx = SimpleNamespace(steps=np.repeat(np.arange(4), 3),
                          step_temp_c={0: -30.0, 1: 10.0, 2: 50.0, 3: 10.2})
    t = thresholds_c(ctx.step_temp_c)[0]
    assert t == -10.0
    col = jump_column(ctx, t)
    hot = np.array([ctx.step_temp_c[s] > t for s in ctx.steps])
    np.testing.assert_array_equal(col.astype(bool), hot)
