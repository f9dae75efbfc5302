"""The oracle separability of the second generator's cases (benchmarks/blind/gen2/separable.py).

White Gaussian noise pools stand in for the shared real recordings' (the oracle reads the
recording's noise scale from the recording itself, as ``diagnose`` does).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import separable as sep
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.protocol import draw_protocol
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.recording import write_recording

SEED = 4242


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    return NoisePools(rng.standard_normal((20_000, 3)), rng.standard_normal((20_000, 3)),
                      rng.standard_normal(2_000))


def _case(tmp: Path, eid: str, m: float, **proto_kw) -> tuple[sep.Oracle, dict, NoisePools]:
    """One case written as ``generate.build`` writes it (sensor first from rng(seed))."""
    pools = _pools()
    rng = np.random.default_rng(SEED)
    sensor = draw_sensor(rng)
    proto = draw_protocol(rng, **proto_kw)
    pat = fx.pattern(rng, len(proto.setpoints_c), 10_000)
    write_recording(tmp / "c.csv", sim.record(proto, sensor, pools, eid, m, pat, SEED))
    key = {"seed": SEED, "effect": eid, "catalogue_id": fx.CATALOGUE_ID[eid], "magnitude": m,
           "pattern": pat, "protocol_detail": asdict(proto)}
    return sep.Oracle(tmp / "c.csv"), key, pools


def test_the_signature_is_the_recordings_own(tmp_path: Path) -> None:
    o, key, pools = _case(tmp_path, "thermal_hysteresis", 8.0, kind="updown")
    s_g, out_e = sep.true_signal_g(key, pools)
    raw = np.column_stack([o.rec.columns[x] for x in ("ax", "ay", "az")])
    noise = o.off(o.U0, o.w((raw - out_e)[:, :, None]))[:, 0]
    # the recording less its noise-free output is noise in the diagnosis' units ...
    assert 0.6 < np.sqrt(np.mean(noise**2)) < 1.4
    # ... and the signature is the hysteresis the generator adds, ± its size per axis
    w = np.asarray(key["pattern"]["axes"])
    assert np.allclose(np.abs(s_g).max(axis=0), np.abs(w) * 8e-6, rtol=1e-6)


def test_a_power_cycle_at_the_turn_is_hysteresis_to_the_oracle(tmp_path: Path) -> None:
    # updown protocols of the generator power-cycle at the top plateau: the offset of the
    # cooling leg is then a session offset from that plateau on, up to the first plateau
    o, key, pools = _case(tmp_path, "thermal_hysteresis", 8.0, kind="updown")
    s_g, _ = sep.true_signal_g(key, pools)
    res = sep.separability(o, key, s_g, ["session_offset", "scale_nonlinearity"], 0.005)
    assert res["base"]["lam_cols"] > 25.0  # well beyond noise on its own
    assert res["session_offset"]["lam_known"] < 0.1 * res["base"]["lam_known"]
    assert res["session_offset"]["power_cols"] < 0.5
    # a rival of another shape leaves it separable
    assert res["scale_nonlinearity"]["power_cols"] > 0.95


def test_outcome_reads_the_rivals_the_diagnosis_named() -> None:
    key = {"catalogue_id": "thermal_hysteresis"}
    withheld = {"findings": [{"effect": "not_identifiable",
                              "where": {"candidates": ["session_offset", "thermal_hysteresis"]}}]}
    assert sep.outcome(withheld, key) == ("not_established", ["session_offset"])
    assert sep.outcome({"findings": [{"effect": "bias_drift"}]}, key) == ("wrong", [])
    assert sep.outcome({"findings": []}, key) == ("missed", [])
    assert sep.outcome({"findings": [{"effect": "thermal_hysteresis"}]}, key)[0] == "right"
    checked = {"findings": [{"effect": "unexplained",
                             "where": {"candidates": ["thermal_hysteresis"]}}]}
    assert sep.outcome(checked, key) == ("not_established", [])


def test_a_lag_beside_a_warm_up_is_judged_against_it(tmp_path: Path) -> None:
    # ThermalLag.not_told_from names a lag only if its amplitude is needed beyond a warm-up
    # after power-on and its own first-plateau nuisance; on a one-way staircase of equal
    # steps those take nearly all of it, and the oracle must say so (issue 22: seed 2 0135
    # was counted a power deficit at λ 199.7 with no rival modelled; 3.2 against this one)
    o, key, pools = _case(tmp_path, "thermal_lag", 400.0, kind="sparse",
                          schedule="sparse18", columns=("chamber_c",), soak_min=10.0)
    s_g, _ = sep.true_signal_g(key, pools)
    res = sep.separability(o, key, s_g, ["self_heating"], 0.005)
    assert res["self_heating"]["rivals_modelled"] == 1
    assert res["base"]["power_cols"] > 0.95
    assert res["self_heating"]["lam_cols"] < 0.2 * res["base"]["lam_cols"]


def test_an_input_only_term_on_a_repeated_order_has_the_slots_as_rival() -> None:
    # slot_settling_alike withholds cross_coupling / scale_nonlinearity whenever the
    # positions are visited in the same order on every plateau (the slots span every
    # function of the position), whichever check reported first
    steps = np.repeat(np.arange(4), 6)
    order = {"steps": steps, "positions": np.tile(np.arange(6), 4),
             "t_s": np.arange(24) * 60.0 + steps * 3600.0}
    turned = {"findings": [{"effect": "not_identifiable",
                            "where": {"candidates": ["cross_coupling", "turntable_geometry"]}}],
              "_order": order}
    status, rivals = sep.outcome(turned, {"catalogue_id": "cross_coupling"})
    assert status == "not_established"
    assert rivals == ["turntable_geometry", sep.SLOT]
    shuffled = {**order, "positions": np.concatenate(
        [np.roll(np.arange(6), k) for k in range(4)])}
    status, rivals = sep.outcome({**turned, "_order": shuffled},
                                 {"catalogue_id": "cross_coupling"})
    assert rivals == ["turntable_geometry"]


def test_a_bend_withheld_for_too_few_levels_has_their_functions_as_rival() -> None:
    # scale_nonlinearity.bends_otherwise withholds a bend whose axes hold ≤ 4 input levels:
    # bias, scale, a² and a³ fit any function of them there (a band of codes included)
    why = ("the structure is a function of each axis's own input, but the protocol holds too "
           "few input levels on the term's axes (x: 4, z: 4; bias, scale, a² and a³ fit any "
           "function of up to 4 levels): ...")
    d = {"findings": [{"effect": "unexplained", "where": {"places": [
        {"not_named": "scale_nonlinearity", "why": why}]}}]}
    status, rivals = sep.outcome(d, {"catalogue_id": "scale_nonlinearity"})
    assert (status, rivals) == ("not_established", [sep.LEVELS + "x,z"])
