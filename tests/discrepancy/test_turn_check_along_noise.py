"""The turn check judges a term's part along the reference against the noise along it (issue 22).

``diagnose._turned_or_bent`` names an input-only term (``cross_coupling``,
``scale_nonlinearity``) only if its part along the reference is still needed after a turn
of the reference. Re-seating the sensor at each visit turns the specific force by a small
angle: scatter across the reference, none along it. The noise model whitens the two alike,
so the pooled F read the along-reference columns against a residual inflated by the
across-reference scatter, and withheld true terms (gen2: the whitened residual along the
reference ~0.86 of its sd across it). ``diagnose.along_log_p`` takes the columns' part
orthogonal to the two across directions and the residual there only. Here, with the
across scatter exaggerated (sd 2 against 1 along), it rejects pure noise at about its
level where the pooled F almost never does, and it finds a small along-reference term the
pooled F misses.
"""

from __future__ import annotations

import importlib

import numpy as np

from benchmarks.blind.gen2 import protocol as gp
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.turntable_geometry import (
    _reading_across_basis,
    turn_columns,
)
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording

dg = importlib.import_module("calibration.discrepancy.diagnose")
ACROSS_SD = 2.0  # whitened sd across the reference (1 along it)
DRAWS = 60


def _setup():
    rng = np.random.default_rng(0)
    pools = NoisePools(rng.standard_normal((20000, 3)), rng.standard_normal((20000, 3)),
                       rng.standard_normal(400))
    proto = gp.Protocol2(name="irregular/oblique36/sensor_c/20min",
                         setpoints_c=(-10.0, 5.0, 20.0, 35.0, 50.0), soak_min=20.0,
                         schedule="oblique36", columns=("sensor_c",), die_tau_s=470.0,
                         n_samples=200, vib_sd_g=(0.0,) * 5, irregular=True,
                         power_cycle_at=None, sensor_noise_g=1e-4)
    pat = {"axes": [1.0, -0.7, -0.4], "from_step": 3, "rows": [0, 1], "axis": 0,
           "band_lo_g": 0.3, "tilt_dir": 0.0, "crack_frac": 0.5}
    cols = sim.record(proto, draw_sensor(np.random.default_rng(3)), pools, None, 0.0, pat, 3)
    pb = build_problem(Recording.from_columns(cols))
    ctx = pb.ctx
    u = ctx.input_g / np.linalg.norm(ctx.input_g, axis=1, keepdims=True)
    Xw, _ = dg._design(pb, [dg.Term("turn", float("nan"), pb.lift(turn_columns(u)))])
    U = stats.orthonormal_basis(Xw)
    X = BY_ID["cross_coupling"].regressors(ctx, 0.0)
    along = np.einsum("nak,na->nk", X, u)[:, None, :] * u[:, :, None]
    Zw = pb.whiten(pb.lift(along))
    C = _reading_across_basis(pb)
    c = np.cross(C[:, :, 0], C[:, :, 1])
    return pb, U, Zw, C, c


def _noise(rng, C, c):
    n = C.shape[0]
    z = rng.standard_normal((n, 3))
    r = (c * z[:, :1] + ACROSS_SD * (C[:, :, 0] * z[:, 1:2] + C[:, :, 1] * z[:, 2:]))
    return r.reshape(-1)


def test_along_the_reference_at_its_level():
    """At 5 %, 60 draws of noise with sd 2 across the reference and 1 along it: the along
    test rejects at most 8 (a test at its level stays at or below that in 99.7 % of runs)
    and at least 1; the pooled F at most 1."""
    pb, U, Zw, C, c = _setup()
    rng = np.random.default_rng(1)
    hits = np.zeros(2, int)
    for _ in range(DRAWS):
        e = stats.project_out(U, _noise(rng, C, c))
        lp_new = dg.along_log_p(pb, U, e, Zw)
        lp_old = float(stats.linear_stats(U, Zw, e, e[:, None])[0])
        hits += [lp_new <= np.log(0.05), lp_old <= np.log(0.05)]
    assert 1 <= hits[0] <= 8
    assert hits[1] <= 1


def test_the_turn_check_names_an_along_term_the_pooled_f_missed():
    """A cross coupling whose part along the reference stands out against the noise along
    it (and not against the pooled scatter) is needed after the turn: the check uses the
    along test."""
    pb, U, Zw, C, c = _setup()
    rng = np.random.default_rng(2)
    e0 = stats.project_out(U, _noise(rng, C, c))
    n = C.shape[0]
    along = (np.sum(Zw.reshape(n, 3, -1) * c[:, :, None], axis=1)[:, None, :]
             * c[:, :, None]).reshape(3 * n, -1)
    sig = stats.project_out(U, along @ np.ones(along.shape[1]))
    e = e0 + 7.0 * sig / np.linalg.norm(sig)  # λ ≈ 49 in the noise along the reference
    lp_new = dg.along_log_p(pb, U, e, Zw)
    lp_old = float(stats.linear_stats(U, Zw, e, e[:, None])[0])
    assert lp_new <= np.log(0.005) < lp_old


def test_the_turn_check_uses_it(monkeypatch):
    """``_turned_or_bent`` reads the along-reference part through ``along_log_p``."""
    calls = []
    real = dg.along_log_p

    def spy(*a):
        calls.append(1)
        return real(*a)

    monkeypatch.setattr(dg, "along_log_p", spy)
    pb, _, _, _, _ = _setup()
    term = dg.Term("cross_coupling", 0.0,
                   pb.lift(BY_ID["cross_coupling"].regressors(pb.ctx, 0.0)))
    f = dg.Finding(effect="cross_coupling", axes=["x"], where={}, explanation="",
                   parameters={}, parameter_sd={}, rmse_before_ug=0.0, rmse_after_ug=0.0,
                   heldout_rmse_before_ug=0.0, heldout_rmse_after_ug=0.0, p_value=0.0,
                   test="", term_effect="cross_coupling")
    dg._turned_or_bent(pb, [term], f, 0.005, {}, [])
    assert calls
