"""Structure found by the family test but withheld as one plateau's is reported (issue 22).

``diagnose._concentrated_on_one_step`` withholds a name when a free change of one plateau
takes the candidate's evidence. The structure must still reach the person reading the
report: one ``not_identifiable`` finding whose candidates are "a change confined to step k"
first and the withheld effects, with the family p, the reason and the experiment that
would separate them — never the verdict "consistent", never the same structure as an
``unexplained`` finding without its candidates (one_step.py).
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.blind.gen2 import detect
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose, one_step
from calibration.discrepancy.diagnose import Finding
from calibration.recording import Recording
from tests.discrepancy.test_temperature_sensor_power import _pattern, _pools, _protocol


@pytest.fixture(scope="module")
def channel_step():
    """A channel step from plateau 2 of a 7-plateau staircase at twice its detectable size
    (seed 2): the family test finds it, the one-plateau check withholds its name."""
    seed, proto, pools = 2, _protocol(), _pools()
    sensor = draw_sensor(np.random.default_rng(seed))
    pat = _pattern(2)
    m_star = detect.minimum_detectable(proto, sensor, pools, "temperature_sensor", pat, seed)
    cols = sim.record(proto, sensor, pools, "temperature_sensor", 2 * m_star, pat, seed)
    return diagnose(Recording.from_columns(cols), n_null=50, seed=seed)


def test_the_withheld_step_is_the_top_finding_with_its_candidates(channel_step):
    d = channel_step
    rejected = [s for s in d.stage_log if s.get("rejected_one_step") is not None]
    assert rejected and rejected[0]["best"] == "temperature_sensor"
    step = rejected[0]["rejected_one_step"]
    out = json.loads(d.to_json())
    assert out["verdict"] == "mismatch"
    top = out["findings"][0]
    assert top["effect"] == "not_identifiable"
    cands = top["where"]["candidates"]
    assert cands[0].startswith(f"a change confined to step {step} (")
    assert "temperature_sensor" in cands
    assert top["where"]["steps"] == [step]
    assert top["evidence"]["p_value"] == pytest.approx(rejected[0]["p_family"], rel=1e-2)
    assert not [f for f in out["findings"] if f["effect"] == "unexplained"
                and f["where"]["steps"] == [step]]  # the same structure, not twice


def test_the_reader_is_told_what_explains_it_and_how_to_separate_them(channel_step):
    text = channel_step.report()
    assert "No mismatch" not in text
    first = text.split("\n1. ", 1)[1].split("\n2. ", 1)[0]
    assert first.startswith("not_identifiable")
    assert "temperature_sensor" in first and "a change confined to step" in first
    assert "cannot tell them apart" in first
    assert "up-down" in first and "reference thermometer" in first  # protocol + own experiment
    assert "nan" not in first  # nothing is modelled: no before/after figures


def test_the_protocol_block_does_not_call_a_candidate_separable(channel_step):
    out = json.loads(channel_step.to_json())
    cands = set(out["findings"][0]["where"]["candidates"])
    assert not cands & set(out["protocol"]["separable"])
    listed = [n["effect"] for n in out["not_identifiable"]]
    assert len(listed) == len(set(listed))  # each effect listed once


# --- placement, on findings alone -------------------------------------------------------
def _pb(n_steps: int = 5):
    steps = np.repeat(np.arange(n_steps), 4)
    ctx = SimpleNamespace(steps=steps, t_s=np.arange(steps.size) * 10.0,
                          step_temp_c={s: 60.0 - 20.0 * s for s in range(n_steps)})
    return SimpleNamespace(ctx=ctx)


def _f(effect: str, **where) -> Finding:
    return Finding(effect=effect, axes=["x"], where={"time_s": [0.0, 1.0], **where},
                   explanation="", parameters={}, parameter_sd={}, rmse_before_ug=1.0,
                   rmse_after_ug=1.0, heldout_rmse_before_ug=1.0, heldout_rmse_after_ug=1.0,
                   p_value=1e-4, test="")


def _rec(effect: str, step: int, p: float) -> one_step.OneStep:
    return one_step.OneStep(effect, step, p, ("x",), np.zeros((1, 1)))


def _report(findings, records, seen=lambda r: True):
    return one_step.report(_pb(), findings, records, Finding, seen, 10.0)


def test_it_replaces_an_unexplained_finding_at_the_same_plateau():
    unexpl = _f("unexplained", steps=[4], places=[{"step": 4, "axis": "x"}])
    out, shown = _report([unexpl], [_rec("vibration_rectification", 4, 1e-7),
                                    _rec("temperature_sensor", 4, 1e-9)])
    assert [f.effect for f in out] == ["not_identifiable"]
    assert out[0].where["candidates"] == ["a change confined to step 4 (-20 °C)",
                                          "temperature_sensor", "vibration_rectification"]
    assert out[0].p_value == 1e-9 and shown == ["temperature_sensor", "vibration_rectification"]


def test_elsewhere_it_follows_the_named_findings_and_keeps_other_structure():
    named, unexpl = _f("outlier", steps=[1]), _f("unexplained", steps=[2],
                                                 places=[{"step": 2, "axis": "x"}])
    out, _ = _report([named, unexpl], [_rec("temperature_rate", 4, 1e-5)])
    assert [f.effect for f in out] == ["outlier", "not_identifiable", "unexplained"]


def test_an_effect_named_or_explained_by_a_later_finding_is_not_repeated():
    named = _f("thermal_hysteresis", steps=[1, 2])
    out, shown = _report([named], [_rec("thermal_hysteresis", 4, 1e-5)])
    assert [f.effect for f in out] == ["thermal_hysteresis"] and shown == []
    out, shown = _report([named], [_rec("temperature_rate", 4, 1e-5)], seen=lambda r: False)
    assert [f.effect for f in out] == ["thermal_hysteresis"] and shown == []


def test_with_no_other_finding_nothing_is_dropped():
    """The family test was significant at its level: whatever a re-test says, the verdict
    is not "consistent"."""
    out, _ = _report([], [_rec("temperature_sensor", 1, 1e-7)], seen=lambda r: False)
    assert [f.effect for f in out] == ["not_identifiable"]
