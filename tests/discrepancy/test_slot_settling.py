"""Issue 22: an input-only name against a settling at each slot of the visiting order.

When every plateau visits the positions in the same order, a settling after each move
that repeats at each slot fits every function of the position (as it does a turn of each
pose, turntable_geometry's protocol-level reason): a nonlinearity is then not named.
"""

from __future__ import annotations

import numpy as np

from calibration.discrepancy import diagnose
from calibration.discrepancy.effects.cross_coupling import cross_coupling_g, pair_products
from calibration.discrepancy.protocol_order import slot_offset_columns, visit_slots
from calibration.discrepancy.slot_settling import SLOT_SETTLING
from calibration.schedules import table1
from simulators import effects as E  # noqa: N812 (short name for many effects)
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
K_XY = 60e-6  # g/g²: ~30 µg at the 45° positions, far above the capture means' noise


def _campaign(order: str, effects=()):
    return simulate_campaign(SensorTruth.adxl355_typical(seed=1, effects=list(effects)),
                             setpoints_c=ONE_WAY, seed=11, position_order=order,
                             position_order_seed=3)


def _with_slot_settling(rec):
    """The recording plus a settling after each move whose size at the k-th visit of every
    plateau is what a_x·a_y coupling makes at the k-th position of Table 1: the worst case
    for the fixed order, where it is that coupling reading for reading; on another order the
    same settling follows the slot, not the position."""
    slot = visit_slots(rec.steps(), rec.columns["position"], rec.t_s)
    off = cross_coupling_g(table1()[slot], np.array([K_XY, 0.0, 0.0]))
    for a, c in enumerate(("ax", "ay", "az")):
        rec.columns[c] = rec.columns[c] + off[:, a]
    return rec


def test_visit_slots_and_what_the_slot_columns_span():
    t = np.arange(12.0)
    steps = np.repeat([0, 1, 2], 4)
    fixed = np.tile([0, 1, 2, 3], 3)
    assert visit_slots(steps, fixed, t).tolist() == [0, 1, 2, 3] * 3
    # two readings of one capture share its slot
    assert visit_slots(np.zeros(4, int), np.array([5, 5, 2, 2]), np.arange(4.0)).tolist() == [
        0, 0, 1, 1]
    ref = table1()

    def rank_left(positions):
        slots = slot_offset_columns(np.repeat(np.arange(3), 24), positions,
                                    np.arange(72.0)).reshape(216, -1)
        X = pair_products(ref[positions]).reshape(216, -1)
        Q = np.linalg.qr(slots)[0]
        return np.linalg.matrix_rank(X - Q @ (Q.T @ X), tol=1e-9)

    assert rank_left(np.tile(np.arange(24), 3)) == 0  # the slots span the products
    rng = np.random.default_rng(0)
    assert rank_left(np.concatenate([rng.permutation(24) for _ in range(3)])) == 3


def test_a_settling_at_each_slot_of_a_repeated_order_is_not_named_cross_coupling():
    """Before issue 22's slot check this recording was named ``cross_coupling``."""
    d = diagnose(_with_slot_settling(_campaign("table")), n_null=30, seed=1)
    assert "cross_coupling" not in [f.effect for f in d.findings]
    f = d.findings[0]
    assert f.effect == "not_identifiable"
    assert f.where["candidates"] == ["cross_coupling", SLOT_SETTLING]
    assert "same order on every plateau" in f.explanation
    assert "different order on some plateaus" in f.explanation
    why = {n["effect"]: n["why"] for n in d.not_identifiable}["cross_coupling"]
    assert why.startswith("not separable from a settling after each move")


def test_the_same_settling_on_a_random_order_is_not_named_cross_coupling():
    """The slot no longer follows the position: the settling is no coupling (here it is
    not found at all: nothing in the catalogue or the scan looks for a per-slot offset)."""
    d = diagnose(_with_slot_settling(_campaign("random")), n_null=30, seed=1)
    assert "cross_coupling" not in [f.effect for f in d.findings]


def test_true_cross_coupling_on_a_random_order_keeps_its_name():
    cc = E.CrossCoupling(k_xy_per_g=K_XY)
    d = diagnose(_campaign("random", [cc]), n_null=30, seed=1)
    assert d.findings[0].effect == "cross_coupling"
    p, s = d.findings[0].parameters, d.findings[0].parameter_sd
    assert abs(p["k_xy_ug_per_g2"] - K_XY * 1e6) < 4 * s["k_xy_ug_per_g2"]


def test_true_cross_coupling_on_the_repeated_order_is_not_separable():
    """The same coupling in Table 1's order every plateau: the data cannot tell it from the
    settling above (the recordings are the same reading for reading but for the noise)."""
    d = diagnose(_campaign("table", [E.CrossCoupling(k_xy_per_g=K_XY)]), n_null=30, seed=1)
    assert d.findings[0].effect == "not_identifiable"
    assert "cross_coupling" in d.findings[0].where["candidates"]


def test_a_recording_too_long_for_the_slot_columns_is_said_before_they_are_built(monkeypatch):
    """The size is judged from the slot count before the (N, 3, 3·slots) columns exist: a
    long repeated schedule has a slot per visit, and a 300 k-reading recording asked for
    548 GiB there."""
    import calibration.discrepancy.slot_settling as ss
    from calibration.discrepancy import stats

    def forbidden(*_a, **_k):
        raise AssertionError("the slot columns were built")

    monkeypatch.setattr(stats, "TALL_BYTES", 1024)
    monkeypatch.setattr(ss, "slot_offset_columns", forbidden)
    d = diagnose(_campaign("table", [E.CrossCoupling(k_xy_per_g=K_XY)]), n_null=30, seed=1)
    assert any("not checked against a settling at each slot of the visiting order: the "
               "recording is too long" in n for n in d.notes), d.notes
