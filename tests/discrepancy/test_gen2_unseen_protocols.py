"""The second generator's unseen protocol family (issue 22): variants a real lab runs that the
default family never draws, drawn without changing what the default family draws.

Recordings use synthetic white noise pools (the benchmark draws them from the shared real
recordings; a test must not name a path outside the repository).
"""

import dataclasses

import numpy as np
import pytest

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import generate, protocol, unseen
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.recording import Recording


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    return NoisePools(rng.standard_normal((5000, 3)), rng.standard_normal((5000, 3)),
                      rng.standard_normal(400))


def _record(proto: protocol.Protocol2, seed: int = 3) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    pat = fx.pattern(rng, len(proto.setpoints_c), 10)
    return sim.record(proto, draw_sensor(rng), _pools(), None, 0.0, pat, seed)


def test_the_default_family_draws_the_same_protocols_and_never_an_unseen_variant():
    unseen_schedules = set(protocol.UNSEEN_SCHEDULES_DEG) | set(protocol.UNSEEN_PAIRS_DEG)
    for seed in range(60):
        a = protocol.draw_protocol(np.random.default_rng(seed))
        b = protocol.draw_protocol(np.random.default_rng(seed), family="default")
        assert a == b
        assert a.schedule not in unseen_schedules
        assert (a.placement_rad, a.sensor_c_offset_c, a.sensor_c_lsb_c) == (5e-6, 0.0, 0.1)
    with pytest.raises(ValueError, match="unknown protocol family"):
        protocol.draw_protocol(np.random.default_rng(0), family="other")


def test_the_default_plan_is_unchanged_and_the_unseen_plan_cycles_the_variants():
    default = generate.plan(False, 1, 40, 2)
    assert all("family" not in s for s in default)
    assert {s["proto_kind"] for s in default if s["kind"] == "null"} == set(protocol.KINDS)
    new = generate.plan(False, 1, 40, 2, protocols="unseen")
    assert [s["seed"] for s in new] == [s["seed"] for s in default]
    assert {s["proto_kind"] for s in new if s["kind"] == "null"} == set(unseen.UNSEEN_KINDS)
    assert all(s["family"] == "unseen" for s in new)


def test_the_six_faces_are_plus_and_minus_each_axis():
    p = protocol.draw_protocol(np.random.default_rng(1), kind="faces6", family="unseen")
    a = np.deg2rad(p.angles_deg())
    ref = np.array([protocol.force_in_sensor(x, y, np.array([0.0, 0.0, 1.0])) for x, y in a])
    assert np.allclose(np.sort(np.round(ref, 12), axis=0),
                       np.sort(np.vstack([np.eye(3), -np.eye(3)]), axis=0))


@pytest.mark.parametrize("variant", unseen.UNSEEN_KINDS)
def test_each_variant_is_what_its_name_says(variant):
    for seed in range(5):
        p = protocol.draw_protocol(np.random.default_rng(seed), kind=variant, family="unseen")
        sp = np.array(p.setpoints_c)
        assert p.name.split("/")[0] == variant
        assert len(p.angles_deg()) == {"faces6": 6, "min12": 12, "tri24": 24, "ring30": 30,
                                       "dense48": 48}.get(variant, len(p.angles_deg()))
        if variant == "hand":
            assert 1e-3 <= p.placement_rad <= 3e-3
        if variant == "narrow":
            assert sp.min() == 0.0 and sp.max() == 40.0
        if variant == "few":
            assert len(set(p.setpoints_c)) in (3, 4)
        if variant == "unequal":
            assert np.min(np.diff(np.unique(sp))) >= 3.0
        if variant == "repeat25":
            assert sp[0] == sp[-1] == 25.0
        if variant == "hot_start":
            assert sp[0] == sp.max() and sp[-1] == sp.max() and np.argmin(sp) == len(sp) // 2
        if variant in ("soak5", "soak90"):
            assert p.soak_min == float(variant[4:])
        if variant in ("n10", "n1000"):
            assert p.n_samples == int(variant[1:])
        if variant in ("quiet20", "noisy300"):
            assert p.sensor_noise_g == pytest.approx(float(variant[5:]) * 1e-6)
        if variant == "slowdie":
            assert p.columns == ("chamber_c",) and p.die_tau_s == 900.0
            assert p.soak_min * 60.0 >= 6 * p.die_tau_s
        if variant == "offset_c":
            assert "sensor_c" in p.columns and 2.0 <= abs(p.sensor_c_offset_c) <= 5.0
            assert p.sensor_c_lsb_c == 0.0625


def test_an_effects_constraints_are_kept_and_no_variant_overrides_them():
    for seed in range(40):
        rng = np.random.default_rng(seed)
        p = protocol.draw_protocol(rng, kind="updown", columns=("sensor_c",), soak_min=10.0,
                                   family="unseen")
        assert p.columns == ("sensor_c",) and p.soak_min == 10.0
        sp = np.array(p.setpoints_c)
        assert p.power_cycle_at is not None and np.argmax(sp) > 0  # it turns: up, then down
        q = protocol.draw_protocol(np.random.default_rng(seed), schedule="oblique36",
                                   family="unseen")
        assert q.schedule in ("oblique36", *unseen.OBLIQUE_SCHEDULES)


def test_a_hand_placed_recording_declares_its_tolerance_and_scatters_by_it():
    p = protocol.draw_protocol(np.random.default_rng(4), kind="hand", family="unseen")
    fixture = dataclasses.replace(p, placement_rad=5e-6)
    hand, fixed = _record(p), _record(fixture)
    assert "ref_tol_deg" in hand and "ref_tol_deg" not in fixed
    assert hand["ref_tol_deg"][0] == pytest.approx(np.rad2deg(np.sqrt(2) * p.placement_rad),
                                                   abs=1e-3)
    rec = Recording.from_columns(hand)  # the reader takes the declared tolerance
    assert len(rec.t_s) == len(hand["t_s"])
    # Same noise draws, the seating scatter alone differs: readings move by ~ mrad × g.
    moved_g = np.abs(hand["ax"] - fixed["ax"])
    assert np.median(moved_g) > 0.2 * p.placement_rad


def test_an_offset_sensor_channel_is_offset_and_on_its_own_grid():
    p = protocol.draw_protocol(np.random.default_rng(2), kind="offset_c",
                               columns=("sensor_c",), family="unseen")
    plain = dataclasses.replace(p, sensor_c_offset_c=0.0)
    off, ref = _record(p)["sensor_c"], _record(plain)["sensor_c"]
    assert np.median(off - ref) == pytest.approx(p.sensor_c_offset_c, abs=0.05)


def test_a_slow_die_on_chamber_air_is_drawn_by_name_only_and_keyed_as_a_lag():
    drawn = {protocol.draw_protocol(np.random.default_rng(s), family="unseen").name.split("/")[0]
             for s in range(400)}
    assert "slowdie" not in drawn and len(drawn) == len(unseen.UNSEEN_KINDS) - 1
    slow = protocol.draw_protocol(np.random.default_rng(0), kind="slowdie", family="unseen")
    assert unseen.lagging_die(slow)
    assert not unseen.lagging_die(dataclasses.replace(slow, die_tau_s=20.0))
    assert not unseen.lagging_die(dataclasses.replace(slow, columns=("chamber_c", "sensor_c")))
    # 6 τ of soak still leave the die behind the air by more than the chamber channel's LSB
    rng = np.random.default_rng(1)
    sc = sim.scene(slow, None, 0.0, fx.pattern(rng, len(slow.setpoints_c), 10), 1)
    assert np.median(np.abs(sc.air_c - sc.die_c)) > 0.01
