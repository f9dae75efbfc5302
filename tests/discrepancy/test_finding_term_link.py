"""A finding and its model term are kept or removed together, whatever the finding's label.

A finding re-labelled ``not_identifiable`` (a turn of the reference, fits alike, a lag's
gains) still reports a term in the model. The filters that withdraw terms after the
forward selection (physics checks, the scan's outlier check, the demotion of a term that
leaves structure at its own places) go by the finding's link to its term
(``Finding.term_keys``), not by its label: by label, the re-labelled finding was dropped
while its term stayed in the model ("with findings" residuals that no finding explains,
and a note calling ``not_identifiable`` an effect).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from calibration.discrepancy import diagnose
from calibration.discrepancy.diagnose import Finding, Term, _leaves_its_own_places, withdraw
from calibration.discrepancy.effects import BY_ID
from simulators import effects as E  # noqa: N812 (as the other discrepancy tests)
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


def _tilted_with_a_pose_offset(offset_ug: float):
    """A tilted table (50, −30 µrad; in the minimal-rotation convention, a turn smooth in
    the reference) visited in the same order on every plateau, plus an offset of one pose's
    z output (position 1, reference in the x–y plane: across it)."""
    tilt = E.TurntableGeometry(base_tilt_rad=np.array([50e-6, -30e-6]), through_poses=False)
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=6, effects=[tilt]),
                            setpoints_c=ONE_WAY, seed=16)
    at_pose = rec.columns["position"] == 1
    rec.columns["az"] = rec.columns["az"] + np.where(at_pose, offset_ug * 1e-6, 0.0)
    return rec


def _modelled(f) -> bool:
    """What a person reads as "modelled": a catalogue name, or "It is modelled (with ...)"."""
    return f.effect in BY_ID or "It is modelled" in f.explanation


def test_a_relabelled_finding_leaves_the_model_with_its_term():
    """The turn is first reported as ``not_identifiable`` (cross_coupling or
    turntable_geometry, modelled with the cross_coupling term); the scan then finds the
    pose offset at one of that finding's own positions, so the term is demoted. The report
    must then model nothing it does not list."""
    d = diagnose(_tilted_with_a_pose_offset(100.0), n_null=30, seed=6)
    assert not any(n.startswith("not_identifiable") for n in d.notes)
    demoted = [n for n in d.notes if "after it, structure remains" in n]
    assert demoted and demoted[0].startswith("cross_coupling not named or modelled")
    # The structure the demoted term was fitted to is reported where it is, with the
    # demoted effect as a candidate: seen, not established.
    unexplained = [f for f in d.findings if f.effect == "unexplained"]
    assert unexplained and unexplained[0].where["candidates"] == ["cross_coupling"]
    assert "not named: cross_coupling" in unexplained[0].explanation
    if not any(_modelled(f) for f in d.findings):
        # nothing listed as modelled: the residuals "with findings" are the base model's
        np.testing.assert_allclose(d.residuals_after_ug, d.residuals_before_ug, atol=1e-6)
        assert d.final_rmse_ug == d.rmse_ug
    linked = {k for f in d.findings for k in f.term_keys}
    assert linked == {t.key for t in d.terms}


def test_without_the_pose_offset_the_relabelled_finding_and_its_term_stay():
    d = diagnose(_tilted_with_a_pose_offset(0.0), n_null=30, seed=6)
    turned = [f for f in d.findings if f.effect == "not_identifiable"]
    assert turned and "turntable_geometry" in turned[0].where["candidates"]
    assert turned[0].term_keys == {("cross_coupling", ())}
    assert {t.key for t in d.terms} == {k for f in d.findings for k in f.term_keys}
    assert d.final_rmse_ug < d.rmse_ug


def _finding(effect: str, term: str, rows=(), steps=(), positions=()) -> Finding:
    return Finding(effect=effect, axes=["x"], where={"steps": list(steps),
                                                     "positions": list(positions),
                                                     "time_s": [0.0, 1.0]},
                   explanation="", parameters={}, parameter_sd={}, rmse_before_ug=1.0,
                   rmse_after_ug=1.0, heldout_rmse_before_ug=1.0, heldout_rmse_after_ug=1.0,
                   p_value=1e-6, test="", rows=list(rows), term_effect=term)


def _term(effect: str, rows=()) -> Term:
    return Term(effect, 0.0, np.zeros((4, 1)), tuple(rows))


def test_withdraw_takes_a_term_and_its_finding_together_whatever_the_label():
    terms = [_term("cross_coupling"), _term("outlier", (3,)), _term("outlier", (7,)),
             _term("bias_drift")]
    findings = [_finding("not_identifiable", "cross_coupling"),  # re-labelled, still modelled
                _finding("outlier", "outlier", rows=(3, 7)),  # two readings, one finding
                _finding("bias_drift", "bias_drift"),
                _finding("unexplained", "")]  # nothing modelled: never withdrawn with a term
    kept_t, kept_f, gone = withdraw(terms, findings, {("cross_coupling", ())})
    assert [t.key for t in kept_t] == [("outlier", (3,)), ("outlier", (7,)), ("bias_drift", ())]
    assert [f.effect for f in kept_f] == ["outlier", "bias_drift", "unexplained"]
    assert gone == {("cross_coupling", ())}
    # one reading of a merged finding: the finding goes, and the other reading's term with it
    kept_t, kept_f, gone = withdraw(terms, findings, {("outlier", (3,))})
    assert [t.key for t in kept_t] == [("cross_coupling", ()), ("bias_drift", ())]
    assert [f.effect for f in kept_f] == ["not_identifiable", "bias_drift", "unexplained"]
    assert gone == {("outlier", (3,)), ("outlier", (7,))}


def test_structure_left_at_a_relabelled_findings_own_positions_demotes_its_term():
    pb = SimpleNamespace(ctx=SimpleNamespace(step_ids=[0, 1, 2], positions=np.arange(6)))
    findings = [_finding("not_identifiable", "scale_nonlinearity", steps=(0, 1, 2),
                         positions=(1, 3)),
                _finding("bias_drift", "bias_drift", steps=(0, 1, 2), positions=range(6)),
                _finding("unexplained", "", positions=(1,))]
    assert _leaves_its_own_places(pb, findings, [{"position": 1, "axis": "z"}]) == {
        ("scale_nonlinearity", ())}
    assert _leaves_its_own_places(pb, findings, [{"position": 2, "axis": "z"}]) == set()
