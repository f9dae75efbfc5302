"""A plateau's heating/cooling direction is the chamber's excursion to it (issue 22).

With soaks shorter than ~3 die time constants the die is still moving when the readings are
taken: cooled from room temperature towards −20 °C, it is still at about −9 °C there and
reads about −12 °C on the next plateau (−11 °C, reached by heating). Plateau medians then
put the first two plateaus' directions the wrong way round, and a hysteresis at eight times
its detectable size (second generator, 5-min soaks, τ 745 s) was named ``session_offset``
or ``temperature_rate``, never ``thermal_hysteresis`` (0/20; 30/30 with the setpoints:
``benchmarks.blind.gen2.name_margin``). Synthetic noise pools, as in
test_rate_follows_the_die.py.
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
from calibration.discrepancy.against import _locate
from calibration.discrepancy.context import base_context
from calibration.recording import Recording

SETPOINTS_C = (-20.0, -11.0, -2.0, 7.0, 16.0, 25.0, 34.0, 43.0, 52.0, 61.0, 70.0,
               61.0, 52.0, 43.0, 34.0, 25.0, 16.0, 7.0, -2.0, -11.0, -20.0)
H_UG = 8.0


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _protocol() -> protocol.Protocol2:
    """Up-down, sensor_c only, 5-min soaks on a die of τ = 745 s (soak < τ)."""
    return protocol.Protocol2(
        name="soak5/oblique36/updown/sensor_c/5min", setpoints_c=SETPOINTS_C, soak_min=5.0,
        schedule="oblique36", columns=("sensor_c",), die_tau_s=745.0, n_samples=200,
        vib_sd_g=tuple(0.0 for _ in SETPOINTS_C), irregular=False, power_cycle_at=None,
        sensor_noise_g=90e-6)


def _case(seed: int = 0, h_ug: float = H_UG) -> tuple[Recording, np.ndarray]:
    rng = np.random.default_rng(2200 + seed)
    pr = _protocol()
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(SETPOINTS_C), 10)
    cols = sim.record(pr, sensor, _pools(), "thermal_hysteresis", h_ug, pat, seed)
    direction = sim.scene(pr, "thermal_hysteresis", h_ug, pat, seed).direction
    return Recording.from_columns(cols), direction


def _context(rec: Recording):
    ref = np.column_stack([rec.columns[k] for k in ("ref_x", "ref_y", "ref_z")])
    return base_context(rec, "reference", ref)


def test_the_direction_is_the_setpoints_excursion_when_the_die_lags():
    rec, truth = _case()
    ctx = _context(rec)
    medians = [ctx.step_temp_c[s] for s in ctx.step_ids]
    assert medians[1] < medians[0]  # the die still cooling on the first heating plateau
    np.testing.assert_array_equal(ctx.direction, truth)


def test_without_setpoints_the_plateau_medians_decide():
    rec, _ = _case()
    cols = {k: v for k, v in rec.columns.items() if k != "setpoint_c"}
    ctx = _context(Recording.from_columns(cols))
    first, second = ctx.step_ids[:2]
    assert ctx.direction[ctx.steps == second][0] == -1.0  # read from the lagging medians


def test_a_hysteresis_under_short_soaks_is_named_hysteresis():
    rec, _ = _case()
    d = diagnose(rec, seed=0, n_null=100)
    assert [f.effect for f in d.findings][:1] == ["thermal_hysteresis"], (
        [(f.effect, f.where.get("candidates")) for f in d.findings], d.notes)


def test_against_locates_by_the_same_directions():
    """``diagnose --against`` reports its residual by heating/cooling with the same reading
    of direction: a residual of 2 noise units on heating plateaus and 1 on cooling ones is
    located so, not mixed by the lagging plateau medians."""
    rec, truth = _case()
    steps = rec.steps()
    z = np.where(truth > 0, 2.0, 1.0)[:, None] * np.ones((len(rec), 3))
    located = _locate(z, np.ones_like(z), steps, rec)
    assert located["by_direction"] == {"cooling": 1.0, "heating": 2.0}
