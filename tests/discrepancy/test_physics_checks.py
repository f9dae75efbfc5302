"""A name only for structure of the named physics' shape (issue 10, docs/diagnosis.md §7).

An ``outlier`` must be isolated: its deviation not predicted by the same position at the
other plateaus, by a smooth function of the reference direction, or by its neighbours in
time. An input-only term (``scale_nonlinearity``) must leave the same residual at every
visit of the same reference direction. The regression cases are the ones
``benchmarks.blind.outside`` named before the checks (cases 0, 7 and 16 of their kinds).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from benchmarks.blind.outside import _lag_channel
from calibration.discrepancy import diagnose, stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.outlier import reading_log_p
from calibration.discrepancy.effects.structure import direction_groups
from calibration.discrepancy.problem import build_problem
from calibration.discrepancy.stats import orthonormal_basis
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
OBLIQUE_XY = {1, 3, 5, 7}  # Table 1 positions with a_x·a_y = ±½


@dataclass
class ZProduct:
    """Outside the catalogue: the z output carries k·a_x·a_y (cross-coupling acts on x, y)."""

    k_per_g: float
    effect_id: str = "z_product"

    def raw_delta_g(self, ctx, truth, rng):
        out = np.zeros((ctx.t_s.size, 3))
        out[:, 2] = self.k_per_g * ctx.ref_g[:, 0] * ctx.ref_g[:, 1]
        return out

    def temperature_delta_c(self, ctx, rng):
        return np.zeros(ctx.t_s.size)


@dataclass
class OrientationHistory:
    """Outside the catalogue: each reading is offset by h × the previous reading's gravity."""

    h_per_g: float
    effect_id: str = "orientation_history"

    def raw_delta_g(self, ctx, truth, rng):
        return self.h_per_g * np.vstack([ctx.ref_g[:1], ctx.ref_g[:-1]])

    def temperature_delta_c(self, ctx, rng):
        return np.zeros(ctx.t_s.size)


def _campaign(truth_seed: int, sim_seed: int, effects: list, **order) -> object:
    truth = SensorTruth.adxl355_typical(seed=truth_seed, effects=effects)
    return simulate_campaign(truth, ONE_WAY, seed=sim_seed, soak_min=30.0, **order)


def _base_basis(rec) -> tuple[object, np.ndarray, np.ndarray]:
    pb = build_problem(rec)
    Xw = pb.X0 * pb.w[:, None]
    U = orthonormal_basis(Xw)
    yw = pb.y * pb.w
    return pb, U, yw - U @ (U.T @ yw)


def test_product_at_oblique_positions_is_unexplained_not_an_outlier(monkeypatch):
    """outside.py z_product case 0: reading 7 (position 7, oblique) was named ``outlier``.

    The structure makes the readings heavier-tailed than Gaussian, so the outlier test's
    null matched to them (stats.reading_tail_dof) does not flag reading 7 at all; the
    physics check that withdraws it is exercised with the Gaussian null (below): Gaussian
    replicates for every family too, since against sign flips of this residual (the
    default) the structure at the other oblique positions keeps reading 7 from being
    flagged at all (stage-1 family p 0.015)."""
    rec = _campaign(31000, 41000, [ZProduct(-7.492123495360357e-05)])
    d = diagnose(rec, n_null=200, seed=0)
    assert "outlier" not in [f.effect for f in d.findings]
    (f,) = [f for f in d.findings if f.effect == "unexplained"]
    assert f.axes == ["z"] and set(f.where["positions"]) <= OBLIQUE_XY
    assert any("heavier-tailed than Gaussian" in n for n in d.notes)
    monkeypatch.setattr(stats, "NULL_TAIL_Z", np.inf)  # the Gaussian null per reading
    monkeypatch.setattr(sys.modules["calibration.discrepancy.diagnose"], "WILD_NULL", False)
    d = diagnose(rec, n_null=200, seed=0)
    assert "outlier" not in [f.effect for f in d.findings]
    (f,) = [f for f in d.findings if f.effect == "unexplained"]
    assert f.axes == ["z"]
    assert set(f.where["positions"]) <= OBLIQUE_XY and 7 in f.where["positions"]
    withdrawn = [p for p in f.where["places"] if p.get("not_named") == "outlier"]
    assert withdrawn and withdrawn[0]["row"] == 7
    assert any("outlier not named at reading 7" in n for n in d.notes)


def test_a_reading_at_a_repeating_oblique_place_is_not_isolated():
    """Module level, three sensors: a product term strong enough (±100 µg at the oblique
    positions) that each of its readings stands off alone; the most deviant one is part of
    the structure (its position or orientation class), whatever the seed."""
    for seed in (5, 6, 7):
        rec = _campaign(seed, 100 + seed, [ZProduct(200e-6)])
        pb, U, e = _base_basis(rec)
        ez = e[pb.axis == 2]
        row = int(np.argmax(np.abs(ez)))
        assert pb.ctx.positions[row] in OBLIQUE_XY
        assert reading_log_p(pb, U, e, row) < np.log(0.01)  # far off on its own
        miss = BY_ID["outlier"].misses(pb, U, e, float(row), {}, ["z"], 0.01)
        assert miss is not None and miss["kind"] in ("position", "direction")
        assert set(miss["positions"]) <= OBLIQUE_XY


def test_isolated_spikes_are_still_outliers():
    """Two disturbed readings at different plateaus and positions (the blind benchmark's
    pattern), on a sensor that also carries the product term: still ``outlier``."""
    rows = (5 * 24 + 10, 8 * 24 + 3)  # an axis-aligned and an oblique reading
    spike = fx.Outlier(size_g=np.array([90e-6, -60e-6, 120e-6]), rows=rows)
    rec = _campaign(11, 111, [spike])
    d = diagnose(rec, n_null=200, seed=11)
    (f,) = [f for f in d.findings if f.effect == "outlier"]
    assert sorted(f.rows) == sorted(rows)
    assert not [n for n in d.notes if "outlier not named" in n]
    pb, U, e = _base_basis(rec)
    for r in rows:
        assert BY_ID["outlier"].misses(pb, U, e, float(r), {}, ["x", "z"], 0.01) is None


def test_a_run_of_readings_drifting_with_a_lagging_channel_is_not_an_outlier(monkeypatch):
    """outside.py lagging_channel case 16: readings 22, 23 (the end of the first plateau,
    where the whole run drifts) were named ``outlier``. A channel lagging the die by τ
    leaves ∂output/∂T·τ·dT/dt on each axis: a rate term whose gains are locked to the
    model's own temperature slope, so it is never ``temperature_rate`` by name either
    (issue 22): it is reported as not separable from a lagging channel (with its τ) or,
    when the rate term is not selected, as structure where it is (``unexplained``). The
    same with the null matched to the readings' own tails and with the Gaussian null."""
    tau_s = 776.1924110859652
    rec = _lag_channel(_campaign(31016, 41016, []), tau_s)
    for tail_z in (None, np.inf):
        if tail_z is not None:
            monkeypatch.setattr(stats, "NULL_TAIL_Z", tail_z)
        d = diagnose(rec, n_null=200, seed=16)
        names = [f.effect for f in d.findings]
        assert d.mismatch and "outlier" not in names and "temperature_rate" not in names
        lag = [f for f in d.findings if f.effect == "not_identifiable"
               and any("lagging by τ" in c for c in f.where["candidates"])]
        assert lag or "unexplained" in names, names
        for f in lag:
            assert "temperature_rate" in f.where["candidates"]
            assert 0.5 * tau_s < f.where["lag_tau_s"] < 1.5 * tau_s


def test_orientation_history_is_not_a_nonlinearity():
    """outside.py orientation_history case 7: named ``scale_nonlinearity`` (y, K2) before; the
    two visits of +y (positions 0 and 18, different previous positions) differ."""
    rec = _campaign(31007, 41007, [OrientationHistory(-1.8922124858747418e-05)])
    d = diagnose(rec, n_null=200, seed=7)
    assert "scale_nonlinearity" not in [f.effect for f in d.findings]
    (f,) = [f for f in d.findings if f.effect == "unexplained"]
    assert {0, 18} <= set(f.where["positions"]) and "y" in f.axes
    assert any("scale_nonlinearity not named" in n for n in d.notes)


def test_a_true_nonlinearity_is_still_named():
    """The same sensor with a real K2 on y instead: same residual at both +y visits."""
    nl = fx.ScaleNonlinearity(k2_per_g=np.array([0.0, 25e-6, 0.0]))
    # a seeded order per plateau: in one order a settling at each slot fits it as well
    d = diagnose(_campaign(31007, 41007, [nl], position_order="random",
                           position_order_seed=3), n_null=200, seed=7)
    assert [f.effect for f in d.findings] == ["scale_nonlinearity"]
    assert not [n for n in d.notes if "not named" in n]


def test_table1_visits_each_axis_direction_twice():
    rec = _campaign(1, 2, [])
    groups = direction_groups(rec.positions(), rec.ref_g)
    assert sorted(groups) == [[0, 18], [2, 10], [4, 22], [6, 14], [8, 16], [12, 20]]
