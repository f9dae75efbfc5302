"""``temperature_rate`` has the second generator's shape: the die's rate, per axis (issue 22).

The second generator's rate effect is ``w_i × dT_die/dt`` with the die a first-order lag
(τ = 600 s here) of the chamber air. With both channels recorded, the regressor must be
the rate of ``sensor_c`` (which follows the die) as it decays within each plateau — not
the chamber's, which holds on a plateau (a rate from it would be ≈ 0: "not identifiable",
and the structure left to hysteresis), and not one slope per plateau (the decay within a
plateau is ±20 % of it at τ = 600 s). Regression guard: passes on the branch base too; the
benchmark that backs it is ``benchmarks.blind.gen2.exact_regressors`` (the generator's
exact rate in place of this regressor changed no top finding, 22/22). Synthetic noise
pools, as in test_gen2_power.py.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.discrepancy.context import base_context
from calibration.discrepancy.effects.temperature_rate import reading_rate_c_per_min
from calibration.recording import Recording

RATE_UG_PER_C_PER_MIN = 20.0


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _case(seed: int = 0) -> tuple[Recording, np.ndarray]:
    """An up-down staircase, both channels, 10-min soaks, the die 600 s behind the air."""
    rng = np.random.default_rng(900 + seed)
    pr = protocol.draw_protocol(rng, kind="updown", schedule="dense24",
                                columns=("chamber_c", "sensor_c"), soak_min=10.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "irregular": False, "die_tau_s": 600.0,
                               "vib_sd_g": tuple(0.0 for _ in pr.setpoints_c)})
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(pr.setpoints_c), 10)
    cols = sim.record(pr, sensor, _pools(), "temperature_rate", RATE_UG_PER_C_PER_MIN, pat, seed)
    die_rate = sim.scene(pr, "temperature_rate", RATE_UG_PER_C_PER_MIN, pat, seed)
    return Recording.from_columns(cols), die_rate.die_rate_c_per_min


def test_the_rate_regressor_is_the_dies_rate_within_each_plateau():
    rec, die_rate = _case()
    ref = np.column_stack([rec.columns[k] for k in ("ref_x", "ref_y", "ref_z")])
    ctx = base_context(rec, "reference", ref)
    rate = reading_rate_c_per_min(ctx)
    rel_rms = np.sqrt(np.mean((rate - die_rate) ** 2) / np.mean(die_rate**2))
    assert rel_rms < 0.03  # measured 0.9 %; one slope per plateau would be ~10 %
    on = ctx.steps == 3
    air_slope = np.polyfit(ctx.t_s[on] / 60.0, rec.columns["chamber_c"][on], 1)[0]
    assert abs(air_slope) < 0.1 * np.mean(np.abs(die_rate[on]))  # the air holds


def test_a_rate_effect_on_an_up_down_staircase_is_named_rate():
    """Not hysteresis: that name is what a chamber-based rate (≈ 0) would leave."""
    rec, _ = _case()
    d = diagnose(rec, seed=0, n_null=100)
    assert [f.effect for f in d.findings] == ["temperature_rate"], d.notes
    f = d.findings[0]
    assert set(f.axes) <= {"x", "y", "z"}
