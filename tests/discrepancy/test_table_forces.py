"""A force set by the table's angle is neither a turn of the table nor a product of inputs.

The second generator's unseen ``cable_strain`` (a cable wound round the inner table axis
pulls by ``w·sin(α + φ)``) was named ``turntable_geometry`` 4 and ``cross_coupling`` 4 times
in 300 unseen outside effects. What tells it apart, physically (issue 22): one tilt of the
base turns every sweep of the table by the same angle (``turntable_circles.same_tilt_chi2``),
a product of the inputs follows the reference along a sweep; a cable's pull is constant
along each sweep of the outer axis and differs between sweeps.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.blind.gen2 import detect, protocol
from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2 import unseen_effects as ux
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import stats
from calibration.discrepancy.diagnose import Term, _design
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects import turntable_circles as tc
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording

UP = np.array([0.0, 0.0, 1.0])


def _table(schedule: str) -> tuple[np.ndarray, np.ndarray]:
    ang = np.deg2rad(protocol.Protocol2(
        "x", (0.0,), 1.0, schedule, ("sensor_c",), 1.0, 20, (0.0,), False, None, 1e-5
    ).angles_deg())
    return ang, np.array([protocol.force_in_sensor(a, b, UP) for a, b in ang])


def _per_circle_tilt(ref: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """(C,2) each circle's tilt-shape coefficients fitted to ``delta`` (noise-free)."""
    axes = tc.sweep_circles(ref)
    circle = tc.circle_of_pose(ref, axes)
    X = tc.shape_columns(ref, np.ones(len(ref)), circle, axes, tc.SHAPE_TILT)
    on = circle >= 0
    A = X[on].reshape(-1, X.shape[2])
    return np.linalg.lstsq(A, delta[on].ravel(), rcond=None)[0].reshape(-1, 2)


@pytest.mark.parametrize("schedule", sorted(protocol.SCHEDULES_DEG))
def test_one_tilt_turns_every_sweep_by_the_same_angle(schedule):
    ang, ref = _table(schedule)
    up = fx.lab_up("turntable_tilt", 50.0, {"tilt_dir": 0.7})
    tilt = np.array([protocol.force_in_sensor(a, b, up) for a, b in ang]) - ref
    t = _per_circle_tilt(ref, tilt)
    cov = np.eye(t.size) * 1e-12  # 1 µrad per coefficient
    chi2, dof = tc.same_tilt_chi2(t, cov)
    assert dof == len(t) - 1 >= 2
    assert chi2 < 1e-3  # exact: |t| = 50 µrad on every sweep
    assert np.allclose(np.linalg.norm(t, axis=1), 50e-6, rtol=1e-3)


@pytest.mark.parametrize("schedule", sorted(protocol.SCHEDULES_DEG))
def test_a_cable_turns_the_sweeps_by_different_angles(schedule):
    """Its part along each sweep's axis is a tilt's t∥ there, of a different size per sweep."""
    ang, ref = _table(schedule)
    pull = np.sin(ang[:, 0] + 0.4)[:, None] * np.array([1.0, -0.7, 0.9]) * 50e-6
    t = _per_circle_tilt(ref, pull)
    chi2, dof = tc.same_tilt_chi2(t, np.eye(t.size) * 1e-12)
    assert chi2 > 100.0 * dof


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    return NoisePools(rng.standard_normal((20000, 3)), rng.standard_normal((20000, 3)),
                      rng.standard_normal(400))


def _case(seed: int, eid: str, multiple: float) -> Recording:
    rng = np.random.default_rng(700 + seed)
    pr = protocol.draw_protocol(rng, kind="irregular", schedule="dense24",
                                columns=("sensor_c",), soak_min=20.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "vib_sd_g": tuple(0.0 for _ in pr.setpoints_c)})
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(pr.setpoints_c), 10) | ux.unseen_pattern(seed, pr.setpoints_c)
    m = multiple * detect.minimum_detectable(pr, sensor, _pools(), eid, pat, seed)
    return Recording.from_columns(sim.record(pr, sensor, _pools(), eid, m, pat, seed))


def _after_products(rec: Recording):
    """``cross_coupling``'s sweep check with its term in the model."""
    pb = build_problem(rec)
    eff = BY_ID["cross_coupling"]
    term = Term("cross_coupling", float("nan"),
                pb.lift(eff.regressors(pb.ctx, float("nan"))))
    Xw, yw = _design(pb, [term])
    U = stats.orthonormal_basis(Xw)
    return eff._offset_per_sweep(pb, U, yw - U @ (U.T @ yw), 0.005)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_cable_needs_an_offset_per_sweep_after_the_products(seed):
    found = _after_products(_case(seed, "cable_strain", 2.0))
    assert found is not None and "sweep" in found["why"]


@pytest.mark.parametrize("seed", [0, 1])
def test_a_true_cross_coupling_needs_none(seed):
    assert _after_products(_case(seed, "cross_coupling", 4.0)) is None
