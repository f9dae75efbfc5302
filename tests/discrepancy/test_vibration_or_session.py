"""A bias step where the recorded vibration power steps is not a power cycle (issue 22), a
power cycle where the vibration does not change stays one, and a die's warm-up after
power-on is not named a lag.

Recordings from the project's blind generator (benchmarks/blind): the ``oneway`` protocol
runs the compressor (0.5 mg rms) on the four plateaus below 0 °C, so its vibration power
steps at the boundary into step 4.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace

import numpy as np
import pytest

from benchmarks.blind import twin
from benchmarks.blind.catalogue import Concealed
from benchmarks.blind.generate import sensor
from benchmarks.blind.protocols import PROTOCOLS, Protocol
from calibration.discrepancy import diagnose
from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.vibration_rectification import vibration_power_g2
from calibration.recording import Recording
from simulators import effects as fx
from simulators.campaign_sim import RigPhysics
from tests.discrepancy.test_protocol import ctx_of

N_NULL = 100
OFFSET_G = np.array([150e-6, -120e-6, 90e-6])  # ~6× the detectable size of a step here


def _without_session(rec: Recording) -> Recording:
    cols = {k: v for k, v in rec.columns.items() if k != "session"}
    return Recording.from_columns(cols)


def _session_step(protocol, from_step: int, seed: int) -> dict:
    """A bias jump from plateau ``from_step`` on, the recording without a session column."""
    proto = replace(protocol, power_cycle_at_step=from_step)
    off = np.vstack([np.zeros(3), OFFSET_G])
    eff = Concealed(fx.SessionOffset(offsets_g=off), {})
    rec = _without_session(twin.recording(proto, sensor(seed, None), eff, seed))
    return json.loads(diagnose(rec, seed=0, n_null=N_NULL).to_json())


def _top(d: dict) -> dict:
    assert d["findings"], d
    return d["findings"][0]


@pytest.mark.parametrize("seed", [100194, 100193])
def test_a_rectified_offset_at_the_compressor_stop_is_not_a_power_cycle(seed):
    proto = PROTOCOLS["oneway"]
    c = OFFSET_G / proto.vib_cold_sd_g**2
    eff = Concealed(fx.VibrationRectification(c_per_g=c), {})
    rec = twin.recording(proto, sensor(seed, None), eff, seed)
    d = json.loads(diagnose(rec, seed=0, n_null=N_NULL).to_json())
    named = [f["effect"] for f in d["findings"]]
    assert "session_offset" not in named, d["findings"]
    f = _top(d)
    assert f["effect"] in ("vibration_rectification", "not_identifiable")
    if f["effect"] == "not_identifiable":
        assert {"session_offset", "vibration_rectification"} <= set(f["where"]["candidates"])


def test_a_power_cycle_where_the_vibration_steps_is_not_named_alone():
    """The converse: a real jump at the compressor's stop cannot be told from rectification
    either, so neither is named alone."""
    d = _session_step(PROTOCOLS["oneway"], 4, 100194)
    f = _top(d)
    assert f["effect"] == "not_identifiable", d["findings"]
    assert {"session_offset", "vibration_rectification"} <= set(f["where"]["candidates"])


@dataclass(frozen=True)
class _SteadyVibration(Protocol):
    """A protocol whose rig vibrates at the cold level on every plateau."""

    def physics(self) -> RigPhysics:
        return RigPhysics(die_tau_s=self.die_tau_s,
                          vib_sd_g_by_step=(self.vib_cold_sd_g,) * len(self.setpoints_c))


def test_a_power_cycle_under_constant_vibration_stays_a_session_offset():
    steady = _SteadyVibration(**{f.name: getattr(PROTOCOLS["oneway"], f.name)
                                 for f in fields(Protocol)})
    d = _session_step(steady, 4, 100194)
    _session_or_temperature_jump(_top(d), 4, d)


def test_a_power_cycle_away_from_the_vibration_step_stays_a_session_offset():
    d = _session_step(PROTOCOLS["oneway"], 7, 100195)
    _session_or_temperature_jump(_top(d), 7, d)


def _session_or_temperature_jump(f: dict, from_step: int, d: dict) -> None:
    """Not the vibration. On a one-way staircase without a session column the plateaus
    from ``from_step`` on are the hot ones: a power cycle there and a jump of the output at
    a temperature (outside the catalogue) are the same step (temperature_jump.py), so the
    finding is not separable, led by session_offset, and modelled from that plateau."""
    assert f["effect"] == "not_identifiable", d["findings"]
    cands = f["where"]["candidates"]
    assert cands[0] == "session_offset" and "jump of the output" in cands[1], cands
    assert "vibration_rectification" not in cands
    assert min(f["where"]["steps"]) == from_step


def test_vibration_power_keeps_real_variation_and_drops_sampling_noise():
    """Sampling scatter of sd² (n = 200) is shrunk to the plateau mean; a vibration that
    doubles half-way through a plateau keeps most of its step."""
    rng = np.random.default_rng(3)
    ctx: DesignContext = ctx_of([-20.0, 0.0, 20.0, 40.0], n_pos=24)
    n = 200
    sigma = np.full(ctx.n, 0.5e-3)
    sigma[(ctx.steps == 2) & (np.arange(ctx.n) % 24 >= 12)] = 0.7e-3
    sd = sigma[:, None] * np.sqrt(rng.chisquare(n - 1, (ctx.n, 3)) / (n - 1))
    ctx.sd_g, ctx.n_samples = sd, np.full(ctx.n, float(n))
    power = vibration_power_g2(ctx)
    quiet = ctx.steps == 0
    assert np.std(power[quiet]) < 0.5 * np.std(sd[quiet] ** 2)
    half = (ctx.steps == 2) & (np.arange(ctx.n) % 24 >= 12)
    jump = power[half].mean() - power[(ctx.steps == 2) & ~half].mean()
    assert jump > 0.8 * (0.7e-3**2 - 0.5e-3**2)
    ctx.n_samples = None  # without n the scatter cannot be split: sd² as recorded
    assert np.array_equal(vibration_power_g2(ctx), sd**2)


def test_a_warm_up_after_power_on_is_not_named_a_lag():
    """A die 2 °C above the chamber, settling with τ = 30 min after power-on, on the
    up-down short-soak campaign: the early plateaus are colder along ∂output/∂T, as behind
    a heating step, but nothing flips with the steps' sign. Not named ``thermal_lag``; if
    the structure is modelled, ``self_heating`` is among its candidates."""
    seed = 100238
    eff = Concealed(fx.SelfHeating(delta_c=2.0, warmup_tau_s=1800.0), {})
    rec = twin.recording(PROTOCOLS["updown_short"], sensor(seed, None), eff, seed)
    d = json.loads(diagnose(rec, seed=0, n_null=N_NULL).to_json())
    assert "thermal_lag" not in [f["effect"] for f in d["findings"]], d["findings"]
    alike = [f for f in d["findings"] if "thermal_lag" in f["where"].get("candidates", [])]
    assert all("self_heating" in f["where"]["candidates"] for f in alike)


@pytest.mark.parametrize(("protocol", "seed", "tau_s"),
                         [("updown_short", 100021, 360.6), ("short_soak", 100006, 384.8)])
def test_a_lag_at_twice_its_detectable_size_is_still_named(protocol, seed, tau_s):
    """The warm-up check does not take a real lag's name: it acts after every step."""
    rec = twin.recording(PROTOCOLS[protocol], sensor(seed, None),
                         Concealed(fx.ThermalLag(tau_s=tau_s), {}), seed)
    d = json.loads(diagnose(rec, seed=0, n_null=N_NULL).to_json())
    assert _top(d)["effect"] == "thermal_lag", d["findings"]
