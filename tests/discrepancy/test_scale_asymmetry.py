"""A scale asymmetry is a ``scale_nonlinearity`` (effects.md), not "unexplained" (issue 22).

A scale factor that differs for positive and negative input, ``k̄·a + Δk·|a|``, is one of the
catalogue's own-axis patterns. On oblique positions |a| is not a², and a² and a³ alone left
6–11 % of its norm² (after the base) as a per-direction structure: the bend check withdrew
the term and the recording was reported "unexplained" at large sizes (or, at 200 µg, also
given a temperature-rate name). Recordings come from the second generator with synthetic
noise pools (as test_gen2_power.py).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.discrepancy.effects.scale_nonlinearity import (
    ScaleNonlinearity,
    asymmetry_axes,
    own_bends,
    scale_nonlinearity_g,
)
from calibration.recording import Recording


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _asymmetric(monkeypatch: pytest.MonkeyPatch, size_ppm: float) -> None:
    """The generator's output gets ``w_i·size·|a_i|`` (the key ``asym``)."""
    plain = fx.output_offset_g

    def offset(eid, m, pat, s):
        if eid != "asym":
            return plain(eid, m, pat, s)
        return np.abs(s["force_g"]) * np.asarray(pat["axes"]) * m * 1e-6

    monkeypatch.setattr(fx, "output_offset_g", offset)


def _record(seed: int, schedule: str, size_ppm: float) -> tuple[Recording, np.ndarray]:
    rng = np.random.default_rng(700 + seed)
    pr = protocol.draw_protocol(rng, kind="oneway", schedule=schedule, columns=("sensor_c",),
                                soak_min=20.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "irregular": False})
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(pr.setpoints_c), 10)
    cols = sim.record(pr, sensor, _pools(), "asym", size_ppm, pat, seed)
    return Recording.from_columns(cols), np.asarray(pat["axes"]) * size_ppm


@pytest.mark.parametrize("seed,schedule", [(0, "oblique36"), (0, "dense24"), (1, "dense24")])
def test_a_large_scale_asymmetry_is_named_with_its_parameter(seed, schedule, monkeypatch):
    """200 ppm of asymmetry: before, "unexplained" (the a², a³ term withdrawn as not a bend)."""
    _asymmetric(monkeypatch, 200.0)
    rec, true_ppm = _record(seed, schedule, 200.0)
    d = diagnose(rec, seed=0, n_null=100)
    names = [f.effect for f in d.findings]
    assert names == ["scale_nonlinearity"], (names, d.notes)
    f = d.findings[0]
    for i, ax in enumerate("xyz"):
        key = f"asym_{ax}_ppm"
        if key in f.parameters:
            assert f.parameters[key] == pytest.approx(true_ppm[i],
                                                      abs=5 * f.parameter_sd[key] + 20.0)


def test_no_asymmetry_column_where_abs_a_is_a_squared():
    """On 0 and ±1 g only, |a| = a²: no column (a min-norm fit would halve K2)."""
    a = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    assert asymmetry_axes(a) == []
    assert own_bends(a).shape == (6, 3, 6)
    assert ScaleNonlinearity().grid(SimpleNamespace(input_g=a)) == [0.0]
    c, s = np.cos(np.deg2rad(30)), np.sin(np.deg2rad(30))
    obl = np.array([[c * np.cos(t), c * np.sin(t), s] for t in np.deg2rad(range(0, 360, 30))])
    assert asymmetry_axes(np.vstack([a, obl])) == [0, 1]  # z: 0, 0.5, ±1 only
    both = SimpleNamespace(input_g=np.vstack([a, obl]))
    assert ScaleNonlinearity().grid(both) == [0.0, 1.0]
    assert ScaleNonlinearity().regressors(both, 0.0).shape[2] == 6
    assert ScaleNonlinearity().regressors(both, 1.0).shape[2] == 8
    five = np.column_stack([np.linspace(-1, 1, 5), np.zeros(5), np.zeros(5)])
    assert asymmetry_axes(five) == []  # 1, a, a², a³, |a| fit any function of 5 levels


def test_the_model_file_term_carries_the_asymmetry():
    """What ``compensate`` subtracts is what the finding reports: |a| × asym on its axis."""
    params = {f"k{p}_{ax}_ug_per_g{p}": 0.0 for p in (2, 3) for ax in "xyz"}
    params["asym_y_ppm"] = 150.0
    spec = ScaleNonlinearity().extension_fields(params)
    a = np.array([[0.0, 0.5, 0.0], [0.0, -0.5, 0.0]])
    out = ScaleNonlinearity().extension_term_g(spec, a)
    assert out[:, 1] == pytest.approx([75e-6, 75e-6])
    assert out == pytest.approx(scale_nonlinearity_g(a, 0.0, 0.0, [0.0, 150e-6, 0.0]))


def test_the_twin_built_from_a_finding_carries_the_asymmetry():
    """The twin's counterpart reads ``asym_*_ppm`` (absent: 0, as in older findings)."""
    from simulators.effects import ScaleNonlinearity as TwinTerm

    params = {f"k{p}_{ax}_ug_per_g{p}": 0.0 for p in (2, 3) for ax in "xyz"}
    assert TwinTerm.from_finding(params).k_abs == pytest.approx([0.0, 0.0, 0.0])
    twin = TwinTerm.from_finding({**params, "asym_z_ppm": -40.0})
    assert twin.k_abs == pytest.approx([0.0, 0.0, -40e-6])
