"""A persistent jump inside a plateau is not a power cycle's session offset (issue 22).

Without a session column ``session_offset`` profiles its jump over plateau boundaries. On
the second generator a crack that appears in the middle of a plateau was named a session
offset: the boundary jump took it, and the readings between the crack and the boundary were
left off. The physics check tests a jump at each reading of the two plateaus beside the
boundary, after the model with the boundary jump.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.discrepancy import stats
from calibration.discrepancy.diagnose import Term, _design
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.session_offset import jump_inside_plateau
from calibration.discrepancy.problem import build_problem
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
STEP = 5


def _with_jump(seed: int, inside: bool, jump_ug: float = 60.0):
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=seed), setpoints_c=ONE_WAY,
                            seed=20 + seed)
    t = rec.columns["t_s"]
    on_step = np.sort(t[rec.steps() == STEP])
    t0 = on_step[len(on_step) // 2] if inside else on_step[0]
    rec.columns["az"] = rec.columns["az"] + np.where(t >= t0, jump_ug * 1e-6, 0.0)
    return rec, float(t0)


def _check(rec, theta: int):
    pb = build_problem(rec)
    eff = BY_ID["session_offset"]
    term = Term("session_offset", float(theta),
                eff.regressors(pb.ctx, float(theta)).reshape(pb.m, -1))
    Xw, yw = _design(pb, [term])
    U = stats.orthonormal_basis(Xw)
    return jump_inside_plateau(pb, U, yw - U @ (U.T @ yw), theta, ["z"], 0.005)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_jump_in_the_middle_of_a_plateau_is_placed_there(seed):
    rec, t0 = _with_jump(seed, inside=True)
    # the boundary jump is fitted at the next plateau (the crack's second half is off) or at
    # the crack's own plateau (its first half is off): either way the place is found
    for theta in (STEP, STEP + 1):
        place = _check(rec, theta)
        assert place is not None and place["kind"] == "time"
        assert STEP in place["steps"] and place["log10_p"] < np.log10(0.005)
        assert place["axes"] == ["z"]
        assert f"inside plateau {STEP}" in place["why"]
        lo, hi = place["time_s"]
        assert lo >= t0 - 1e-6 or hi < t0  # the readings moved lie on one side of the crack


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_jump_at_a_plateau_boundary_passes(seed):
    rec, _ = _with_jump(seed, inside=False)
    assert _check(rec, STEP) is None
