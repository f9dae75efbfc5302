"""A function of the specific force is the same at every visit of a reference direction,
wherever that direction is (issue 22, docs/diagnosis.md §7).

With a reference column, ``structure.visits_differ`` judges an input-only name
(``scale_nonlinearity``, ``cross_coupling``) on every direction the schedule revisits, on
all three axes, not only at the term's own positions and axes: an offset that depends on
the table's pose rather than on the force (a cable wound round the inner axis: several
table angles give +z, each its own offset) leaves its evidence where the products or
powers are zero, and the name fitted elsewhere did not describe it. In norm mode (no
reference) the directions are read from the output and the check stays at the term's own
places: the real OpenAXES test (test_diagnose.py) holds that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.structure import (
    direction_groups,
    extend,
    visits_differ,
    whitened,
)
from calibration.discrepancy.problem import build_problem
from calibration.discrepancy.stats import orthonormal_basis
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
ALPHA = 0.005


@dataclass
class PoseOffset:
    """Outside the catalogue: one table pose (position id) offset on x, z by a fixed amount;
    the other visit of the same direction is not (a cable's pull at one table angle)."""

    position: int
    size_g: float
    per_step: int = 24  # Table 1: the positions in order on every plateau
    effect_id: str = "pose_offset"

    def raw_delta_g(self, ctx, truth, rng):
        out = np.zeros((ctx.t_s.size, 3))
        rows = np.arange(ctx.t_s.size) % self.per_step == self.position
        out[rows, 0] = self.size_g
        out[rows, 2] = -self.size_g
        return out

    def temperature_delta_c(self, ctx, rng):
        return np.zeros(ctx.t_s.size)


def _with_term(rec, effect: str):
    pb = build_problem(rec)
    U = orthonormal_basis(pb.X0 * pb.w[:, None])
    yw = pb.y * pb.w
    e = yw - U @ (U.T @ yw)
    X = BY_ID[effect].regressors(pb.ctx, float("nan"))
    return (pb, *extend(U, e, whitened(pb, X)))


def _campaign(seed: int, effects: list):
    truth = SensorTruth.adxl355_typical(seed=seed, effects=effects)
    return simulate_campaign(truth, ONE_WAY, seed=100 + seed, soak_min=30.0)


def test_a_pose_offset_away_from_the_terms_places_withdraws_the_name():
    """+y is visited at positions 0 and 18; position 0 alone carries 40 µg on x and z. A
    nonlinearity claimed on y at other positions (here: the oblique ones) is still not a
    function of the force: the two +y visits disagree on axes the term does not name."""
    rec = _campaign(3, [PoseOffset(position=0, size_g=40e-6)])
    pb, U, e = _with_term(rec, "scale_nonlinearity")
    assert [0, 18] in direction_groups(pb.ctx.positions, pb.ctx.input_g)
    assert pb.mode == "reference"
    found = visits_differ(pb, U, e, [1, 3, 5, 7], ["y"], ALPHA)
    assert found is not None
    assert {0, 18} <= set(found["positions"]) and {"x", "z"} <= set(found["axes"])
    assert found["log10_p"] < np.log10(ALPHA)
    miss = BY_ID["scale_nonlinearity"].misses(pb, U, e, float("nan"),
                                             {"positions": [1, 3, 5, 7]}, ["y"], ALPHA)
    assert miss is not None and "differs between visits" in miss["why"]


def test_true_force_functions_leave_every_revisit_alike():
    """A real K2 on y, and a real x·y product, over three sensors: no direction the schedule
    revisits disagrees after the term (all directions, all axes tested)."""
    for seed in (5, 6, 7):
        for effect, truth in (
            ("scale_nonlinearity", fx.ScaleNonlinearity(k2_per_g=np.array([0.0, 60e-6, 0.0]))),
            ("cross_coupling", fx.CrossCoupling(k_xy_per_g=60e-6)),
        ):
            pb, U, e = _with_term(_campaign(seed, [truth]), effect)
            assert visits_differ(pb, U, e, [], [], ALPHA) is None, (seed, effect)
