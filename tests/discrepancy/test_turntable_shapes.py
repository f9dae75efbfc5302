"""A table's sweeps found from the references, and the two low-dof shapes of its geometry
(issue 22): a tilted table axis and an encoder error are tested with a few parameters per
sweep circle instead of the free turn of each pose.

Recordings come from the second generator (its two-axis table: inner axis = sensor z,
outer axis = lab x) with synthetic noise pools, as test_gen2_power.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.blind.gen2 import detect, protocol
from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration import schedules
from calibration.discrepancy import diagnose
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects import turntable_circles as tc
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording

UP = np.array([0.0, 0.0, 1.0])


def _table(schedule: str) -> tuple[np.ndarray, np.ndarray]:
    """(P,2) commanded (α, β) rad and (P,3) references of a gen2 schedule."""
    ang = np.deg2rad(protocol.Protocol2(
        "x", (0.0,), 1.0, schedule, ("sensor_c",), 1.0, 20, (0.0,), False, None, 1e-5
    ).angles_deg())
    ref = np.array([protocol.force_in_sensor(a, b, UP) for a, b in ang])
    return ang, ref


@pytest.mark.parametrize("schedule", sorted(protocol.SCHEDULES_DEG))
def test_the_sweeps_of_a_two_axis_table_are_its_outer_axis_at_each_inner_angle(schedule):
    ang, ref = _table(schedule)
    axes = tc.sweep_circles(ref)
    alphas = np.unique(ang[:, 0])
    outer = [protocol.rot_z(a).T @ np.array([1.0, 0.0, 0.0]) for a in alphas]
    assert len(axes) == len(alphas)
    for n in outer:  # each outer axis in the sensor frame is one circle's axis (± n)
        assert max(abs(float(n @ m)) for m in axes) > 1 - 1e-9
    on = tc.circle_of_pose(ref, axes)
    poles = np.abs(ref[:, 2]) > 1 - 1e-9  # β = 0, 180°: on every sweep, so on none
    assert np.all(on[poles] == -1) and np.all(on[~poles] >= 0)


@pytest.mark.parametrize("name", ["six", "sphere48", "sphere200", "sphere1296"])
def test_schedules_without_sweeps_have_no_circles(name):
    assert tc.sweep_circles(schedules.get_schedule(name)) == []


def _span_residual(cols: np.ndarray, delta: np.ndarray) -> float:
    """Relative part of ``delta`` (N,3) outside the span of ``cols`` (N,3,k)."""
    A = cols.reshape(-1, cols.shape[2])
    coef = np.linalg.lstsq(A, delta.ravel(), rcond=None)[0]
    return float(np.linalg.norm(delta.ravel() - A @ coef) / np.linalg.norm(delta))


@pytest.mark.parametrize("schedule", sorted(protocol.SCHEDULES_DEG))
def test_a_tilt_and_an_encoder_error_are_each_their_own_shape(schedule):
    """The exact change of the specific force (gen2's physics, 50 µrad) lies in its shape's
    span on the swept poses, and not in the other's."""
    ang, ref = _table(schedule)
    axes = tc.sweep_circles(ref)
    circle = tc.circle_of_pose(ref, axes)
    on = circle >= 0
    mag = np.ones(len(ref))
    m_urad = 50.0
    up = fx.lab_up("turntable_tilt", m_urad, {"tilt_dir": 0.7})
    tilt = np.array([protocol.force_in_sensor(a, b, up) for a, b in ang]) - ref
    beta = ang[:, 1] + fx.encoder_error_rad("turntable_encoder", m_urad, ang[:, 1])
    enc = np.array([protocol.force_in_sensor(a, b, UP) for a, b in
                    zip(ang[:, 0], beta, strict=True)]) - ref
    cols = {s: tc.shape_columns(ref, mag, circle, axes, s)[on]
            for s in (tc.SHAPE_TILT, tc.SHAPE_ENCODER)}
    assert _span_residual(cols[tc.SHAPE_TILT], tilt[on]) < 1e-4
    assert _span_residual(cols[tc.SHAPE_ENCODER], enc[on]) < 1e-4
    assert _span_residual(cols[tc.SHAPE_ENCODER], tilt[on]) > 0.3
    assert _span_residual(cols[tc.SHAPE_TILT], enc[on]) > 0.3


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    return NoisePools(rng.standard_normal((20000, 3)), rng.standard_normal((20000, 3)),
                      rng.standard_normal(400))


def _case(seed: int, eid: str | None, multiple: float, schedule: str = "dense24"):
    """A varied-order gen2 recording with ``eid`` at ``multiple`` × its detectable size."""
    rng = np.random.default_rng(700 + seed)
    pr = protocol.draw_protocol(rng, kind="irregular", schedule=schedule,
                                columns=("sensor_c",), soak_min=20.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "vib_sd_g": tuple(0.0 for _ in pr.setpoints_c)})
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(pr.setpoints_c), 10)
    m = 0.0
    if eid is not None:
        m = multiple * detect.minimum_detectable(pr, sensor, _pools(), eid, pat, seed)
    return Recording.from_columns(sim.record(pr, sensor, _pools(), eid, m, pat, seed))


def test_the_grid_is_the_shapes_where_the_references_show_sweeps_else_the_free_turn():
    """Where the sweeps are found, the tilt and encoder shapes replace the free turn of each
    pose (issue 22): beside them it added a grid value and the family's heaviest null, and
    its replicates' minimum beat a 2× tilt's own p on the second generator."""
    eff = BY_ID["turntable_geometry"]
    swept = build_problem(_case(1, None, 0.0)).ctx
    assert eff.grid(swept) == [tc.SHAPE_TILT, tc.SHAPE_ENCODER]
    assert eff.regressors(swept, tc.SHAPE_TILT).shape[2] == 2 * 3
    assert eff.regressors(swept, tc.SHAPE_ENCODER).shape[2] == 4 * 3
    faces = build_problem(_case(1, None, 0.0, "faces6")).ctx
    grid = eff.grid(faces)
    assert len(grid) == 1 and np.isnan(grid[0])


@pytest.mark.parametrize(("eid", "shape"), [("turntable_tilt", tc.SHAPE_TILT),
                                            ("turntable_encoder", tc.SHAPE_ENCODER)])
def test_twice_the_detectable_size_is_named_with_its_shape(eid, shape):
    """At 2× the size the exact 2-parameter shape detects at 50 % (gen2's detect.py) the
    sweep shape (6 or 12 dof) names it, and says which. The free turn of each pose alone
    (46 dof, before) missed this encoder error (family p 0.02) and named the tilt without
    its shape."""
    d = diagnose(_case(2, eid, 2.0), seed=2, n_null=100)
    assert [f.effect for f in d.findings] == ["turntable_geometry"]
    p = d.findings[0].parameters
    assert p["shape"] == shape and p["n_circles"] == 3
    assert "sweep circle" in d.findings[0].explanation


def test_no_effect_no_turn():
    d = diagnose(_case(2, None, 0.0), seed=2, n_null=100)
    assert "turntable_geometry" not in [f.effect for f in d.findings]
