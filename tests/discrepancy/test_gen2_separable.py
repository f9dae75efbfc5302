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
