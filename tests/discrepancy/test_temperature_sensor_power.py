"""A step of the temperature channel on the second generator (issue 22).

The generator steps the *recorded* temperature by δ from a plateau on while the output still
follows the die, so the output departs from the model by f(T_rec − δ) − f(T_rec) ≈
−δ·∂f/∂T on those plateaus. The catalogue term (``temperature_sensor``) is that column:

* its shape is the step's (noise-free, the term alone explains the step's whole remnant
  after the base model, and its coefficient is δ);
* with noise, its statistic at the true plateau is the exact-shape λ of the generator's own
  detectability (``detect.py``) within the noise;
* on a one-way staircase of seven plateaus the cubic in T leaves a step near either end
  little room: a free change of one plateau next to it explains most of its remnant. The
  step is found by the family test at twice its detectable size, and it must then be
  reported — named, or as not separable — never a "consistent" verdict (a rejection by
  ``diagnose._concentrated_on_one_step`` is reported by ``one_step.py``).

Noise pools are synthetic (as test_gen2_power.py): the benchmark's come from real recordings
outside the repository.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from benchmarks.blind.gen2 import detect
from benchmarks.blind.gen2 import protocol as gp
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose, stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording

diagnose_mod = importlib.import_module("calibration.discrepancy.diagnose")
STEP = BY_ID["temperature_sensor"]
STAIRCASE_C = (60.0, 43.0, 27.0, 10.0, -7.0, -23.0, -40.0)


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    return NoisePools(rng.standard_normal((20000, 3)), rng.standard_normal((20000, 3)),
                      rng.standard_normal(400))


def _protocol(setpoints_c: tuple[float, ...] = STAIRCASE_C) -> gp.Protocol2:
    return gp.Protocol2(name="staircase_down/dense24/sensor_c/20min", setpoints_c=setpoints_c,
                        soak_min=20.0, schedule="dense24", columns=("sensor_c",),
                        die_tau_s=600.0, n_samples=100, vib_sd_g=(0.0,) * len(setpoints_c),
                        irregular=False, power_cycle_at=None, sensor_noise_g=60e-6)


def _pattern(from_step: int) -> dict:
    return {"axes": [1.0, -0.5, 0.7], "from_step": from_step, "rows": [0, 1], "axis": 0,
            "band_lo_g": 0.3, "tilt_dir": 0.0, "crack_frac": 0.5}


def _noise_free(proto: gp.Protocol2, step_c: float, from_step: int, seed: int) -> Recording:
    """The recording without noise: capture means = the output at the die temperature,
    the channel = die + step (a tiny sd so the base is whitened as a recording's)."""
    pat = _pattern(from_step)
    sc = sim.scene(proto, "temperature_sensor", step_c, pat, seed)
    sensor = draw_sensor(np.random.default_rng(seed))
    y = sim.noise_free_output(sensor, sc, "temperature_sensor", step_c, pat)
    temp = sim.recorded_temperature_c(sc, proto, "temperature_sensor", step_c, pat)
    n = len(sc.t_s)
    cols = {"t_s": sc.t_s, "step": sc.steps.astype(float), "position": sc.positions.astype(float),
            "ref_x": sc.ref_g[:, 0], "ref_y": sc.ref_g[:, 1], "ref_z": sc.ref_g[:, 2],
            "ax": y[:, 0], "ay": y[:, 1], "az": y[:, 2], "n": np.full(n, 100.0),
            "sd_x": np.full(n, 1e-7), "sd_y": np.full(n, 1e-7), "sd_z": np.full(n, 1e-7),
            "sensor_c": temp["sensor_c"]}
    return Recording.from_columns(cols)


def _term_fit(rec: Recording, from_step: int) -> tuple[float, float, float]:
    """(coefficient, its z, share of the base residual's norm² the term explains)."""
    pb = build_problem(rec)
    Xw, yw = diagnose_mod._design(pb, [])
    U = stats.orthonormal_basis(Xw)
    e = yw - U @ (U.T @ yw)
    t = pb.whiten(pb.lift(STEP.regressors(pb.ctx, float(from_step))))[:, 0]
    z = t - U @ (U.T @ t)
    coef = float(z @ e / (z @ z))
    return coef, float(z @ e / np.linalg.norm(z)), float((z @ e) ** 2 / (z @ z) / (e @ e))


@pytest.mark.parametrize("from_step", [2, 3, 5])
def test_the_term_has_the_shape_of_a_step_of_the_recorded_temperature(from_step):
    """Noise-free: the one column explains the step's remnant after the base model (≥ 95 %
    of its norm²) and its coefficient is the step in °C (±10 %, the linearisation)."""
    rec = _noise_free(_protocol(), 0.5, from_step, seed=3)
    coef, _, share = _term_fit(rec, from_step)
    assert share >= 0.95
    assert coef == pytest.approx(0.5, rel=0.10)


def test_a_per_axis_bias_jump_is_not_the_step_shape():
    """The column is locked to ∂output/∂T: a jump of the biases alone (a power cycle) at the
    same plateau is explained far less (so the term is specific, not a free offset)."""
    proto = _protocol()
    pb = build_problem(_noise_free(proto, 0.5, 3, seed=3))
    Xw, yw = diagnose_mod._design(pb, [])
    U = stats.orthonormal_basis(Xw)
    jump = np.zeros((pb.ctx.n, 3))
    jump[pb.ctx.steps >= 3] = [30e-6, -20e-6, 25e-6]
    y = pb.whiten(pb.lift(jump[:, :, None]))[:, 0]
    e = y - U @ (U.T @ y)
    t = pb.whiten(pb.lift(STEP.regressors(pb.ctx, 3.0)))[:, 0]
    z = t - U @ (U.T @ t)
    assert (z @ e) ** 2 / (z @ z) / (e @ e) < 0.5


def test_the_statistic_at_the_true_plateau_is_the_exact_shape_lambda():
    """With noise, at twice the detectable size: z at the true plateau is the generator's
    exact-shape λ (detect.py, true σ) within ±2.5 (one draw), and far beyond the noise."""
    proto, pools, seed, from_step = _protocol(), _pools(), 7, 3
    sensor = draw_sensor(np.random.default_rng(seed))
    pat = _pattern(from_step)
    m_star = detect.minimum_detectable(proto, sensor, pools, "temperature_sensor", pat, seed)
    lam, _ = detect.lam_fn(proto, sensor, pools, "temperature_sensor", pat, seed)
    cols = sim.record(proto, sensor, pools, "temperature_sensor", 2 * m_star, pat, seed)
    _, z, _ = _term_fit(Recording.from_columns(cols), from_step)
    assert abs(abs(z) - lam(2 * m_star)) <= 2.5
    assert abs(z) >= 4.0


@pytest.mark.parametrize("seed", [1, 2])
def test_a_found_step_is_reported_named_or_not_separable_never_consistent(seed):
    """From plateau 2 of 7 the unstepped side is two plateaus: to the cubic in T the step is
    nearly "plateaus 0–1 differ", and a free change of one of them takes most of it. Found
    (p_family ≤ α/2), it is either named or listed as not separable, with mismatch."""
    proto, pools, from_step = _protocol(), _pools(), 2
    sensor = draw_sensor(np.random.default_rng(seed))
    pat = _pattern(from_step)
    m_star = detect.minimum_detectable(proto, sensor, pools, "temperature_sensor", pat, seed)
    cols = sim.record(proto, sensor, pools, "temperature_sensor", 2 * m_star, pat, seed)
    d = diagnose(Recording.from_columns(cols), n_null=50, seed=seed)
    assert d.stage_log and d.stage_log[0]["p_family"] <= 0.005  # the family test found it
    top = d.findings[0] if d.findings else None
    named = top is not None and top.effect == "temperature_sensor"
    listed = (top is not None and top.effect == "not_identifiable"
              and "temperature_sensor" in (top.where.get("candidates") or []))
    assert d.mismatch and (named or listed)
