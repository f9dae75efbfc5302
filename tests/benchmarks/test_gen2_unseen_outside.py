"""The second generator's unseen outside effects (benchmarks/blind/gen2/unseen_effects.py) do
what their docstrings say, through the same scene the recordings are written from, and the
default plan is untouched by them. No real recordings needed (noise-free output only).
"""

from __future__ import annotations

import numpy as np

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import generate
from benchmarks.blind.gen2 import protocol as pr
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2 import unseen_effects as ux
from benchmarks.blind.gen2.sensor import draw_sensor

M_UG = 100.0


def _case(eid: str, kind: str = "updown", schedule: str = "dense24", seed: int = 4):
    rng = np.random.default_rng(seed)
    proto = pr.draw_protocol(rng, kind=kind, schedule=schedule, columns=("sensor_c",),
                             soak_min=20.0)
    pat = fx.pattern(rng, len(proto.setpoints_c), 10)
    pat.update(ux.unseen_pattern(seed, proto.setpoints_c))
    pat["axes"] = [1.0, -0.5, 0.25]
    sensor = draw_sensor(rng)
    sc = sim.scene(proto, eid, M_UG, pat, seed)
    extra = sim.noise_free_output(sensor, sc, eid, M_UG, pat) - sim.noise_free_output(
        sensor, sc, None, 0.0, pat)
    return proto, pat, sc, extra / 1e-6  # µg


def test_every_unseen_effect_is_outside_the_catalogue_and_the_default_set():
    assert not set(ux.UNSEEN_OUTSIDE) & set(fx.UNIT)
    assert not set(ux.UNSEEN_OUTSIDE) & set(fx.OUTSIDE)
    # each changes the output, along the case's per-axis pattern w
    for eid in ux.UNSEEN_OUTSIDE:
        _, pat, _, extra = _case(eid)
        assert np.abs(extra).max() > 1.0, eid
        np.testing.assert_allclose(extra[:, 1], -0.5 * extra[:, 0], atol=1e-9)


def test_the_default_plan_keeps_its_outside_effects_and_case_ids():
    old = generate.plan(False, 2, 5, 2)
    same = generate.plan(False, 2, 5, 2, outside_set="default")
    assert old == same
    assert {s["effect"] for s in old if s["kind"] == "outside"} == set(fx.OUTSIDE)
    new = generate.plan(False, 2, 5, 2, outside_set="unseen")
    assert {s["effect"] for s in new if s["kind"] == "outside"} == set(ux.UNSEEN_OUTSIDE)
    assert sum(s["kind"] == "outside" for s in new) == 2 * 2 * len(ux.UNSEEN_OUTSIDE)


def test_fixture_creep_decays_with_its_time_constant_after_each_move():
    ref = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0]])
    t = np.array([10.0, 20.0, 20.0 + 60.0, 20.0 + 600.0])
    load = ux.creep_load(ref, t, capture_s=0.0, tau_s=60.0)
    # the flip loads the fixture by |Δref|/2 = 1; no new load by staying in the pose
    assert load[0] == 0.0 and np.isclose(load[1], 1.0)
    np.testing.assert_allclose(load[2], np.exp(-1.0), rtol=1e-12)  # one τ after the flip
    assert load[3] < 1e-3 * load[1]
    # in a campaign: the first reading of a plateau follows a soak; the creep there is its
    # own move's only, and readings further into a plateau carry the earlier moves as well
    _, _, sc, extra = _case("fixture_creep")
    assert np.all(extra[:, 0] >= 0.0) and np.ptp(extra[:, 0]) > 10.0


def test_thermal_threshold_jumps_on_every_crossing_both_ways():
    proto, pat, sc, extra = _case("thermal_threshold", kind="updown")
    above = sc.die_c > pat["threshold_c"]
    assert above.any() and (~above).any()
    np.testing.assert_allclose(extra[above, 0], M_UG)
    np.testing.assert_allclose(extra[~above, 0], 0.0)
    # re-occurs on the way down: readings above T* after the hottest plateau carry it too
    hottest = int(np.argmax(proto.setpoints_c))
    assert np.any(above & (sc.steps > hottest))
    # T* lies between two setpoints: every plateau is wholly on one side of it
    for k in np.unique(sc.steps):
        assert len(np.unique(above[sc.steps == k])) == 1


def test_hvac_cycle_repeats_with_its_period_in_time():
    _, pat, sc, extra = _case("hvac_cycle")
    p = pat["hvac_period_s"]
    assert 600.0 <= p <= 2400.0
    state = {"t_s": sc.t_s + p, "ref_g": sc.ref_g, "die_c": sc.die_c, "angles_rad":
             sc.angles_rad, "die_trace_c": sc.die_trace_c, "capture_s": sc.capture_s}
    later = ux.unseen_offset_g("hvac_cycle", M_UG, pat, state) / 1e-6
    np.testing.assert_allclose(later, extra, atol=1e-6)
    assert np.abs(extra[:, 0]).max() <= 1.3 * M_UG


def test_frost_grows_below_the_dew_point_and_sublimates_above_it():
    trace = np.concatenate([np.full(3600, -20.0), np.full(3600, 20.0)])
    f = ux.frost_mass(trace, dew_c=0.0, grow_s=3600.0, decay_s=600.0)
    assert np.all(np.diff(f[:3600]) > 0) and np.all(np.diff(f[3601:]) < 0)
    assert np.isclose(f[3600], 1 - np.exp(-1.0), rtol=1e-3)
    assert f[-1] < 0.01 * f[3600]
    _, pat, sc, extra = _case("frost")
    cold = sc.die_c < pat["dew_c"]
    assert cold.any() and np.all(extra[:, 0] >= 0)
    # the deposit is largest where the die has been cold longest, and outlives the cold
    assert extra[cold, 0].max() > 0 and np.any(extra[~cold, 0] > 1e-3 * extra[cold, 0].max())


def test_cable_strain_follows_the_table_angle_not_the_force():
    _, pat, sc, extra = _case("cable_strain", schedule="dense24")
    up = np.isclose(sc.ref_g[:, 2], 1.0)  # β = 0: α does not change the force
    alphas = np.unique(np.round(sc.angles_rad[up, 0], 6))
    assert len(alphas) >= 2
    per_alpha = [extra[up & np.isclose(sc.angles_rad[:, 0], a), 0] for a in alphas]
    # one gravity direction, different offsets: not a function of the force
    assert np.ptp([v.mean() for v in per_alpha]) > 10.0
    np.testing.assert_allclose(extra[:, 0], M_UG * np.sin(sc.angles_rad[:, 0]
                                                          + pat["cable_phase_rad"]))
