"""A candidate whose fit lies within an earlier term's columns is not added (issue 22).

On the second generator an ADC error confined to a band of codes was first taken by a free
turn of each table pose, then by a cube of each axis's input: a per-pose constant across the
reference is a turn, so beyond the base model the bend's fit lay wholly within the turn's
columns. Fitted together the two cancelled, and the report read "K3 = −364,500 µg/g³" beside
a turn of 11,420 µrad rms. Such a candidate is now reported as found and not told apart.
"""

from __future__ import annotations

import sys

import numpy as np

from calibration.discrepancy.diagnose import (
    Term,
    _outside_earlier_terms,
    _term_coefficients,
    diagnose,
)
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.problem import build_problem

diagnose_mod = sys.modules["calibration.discrepancy.diagnose"]


def _share(pb, earlier: list[Term], term: Term):
    """The share outside ``earlier``, with ``term``'s coefficients fitted beside them."""
    return _outside_earlier_terms(pb, earlier, term,
                                  _term_coefficients(pb, earlier + [term], term)[0])


def _term(pb, effect_id: str) -> Term:
    eff = BY_ID[effect_id]
    theta = eff.grid(pb.ctx)[0]
    return Term(effect_id, theta, eff.regressors(pb.ctx, theta).reshape(pb.m, -1))


def test_the_share_outside_earlier_terms_tells_a_copy_from_another_shape(nonlinear_recording):
    pb = build_problem(nonlinear_recording)
    bend = _term(pb, "scale_nonlinearity")
    rng = np.random.default_rng(0)
    mix = rng.standard_normal((bend.X.shape[1], 3))
    copy = Term("cross_coupling", float("nan"),
                bend.X @ mix + 1e-4 * bend.X.std() * rng.standard_normal((pb.m, 3)))
    share, most = _share(pb, [bend], copy)
    assert share < 0.01 and most == "scale_nonlinearity"
    share, most = _share(pb, [bend], _term(pb, "bias_drift"))
    assert share > 0.5
    assert _share(pb, [], bend) == (1.0, None)


def test_a_candidate_within_an_earlier_term_is_reported_not_added(monkeypatch,
                                                                 nonlinear_recording):
    rec = nonlinear_recording
    assert diagnose(rec, n_null=30, seed=1).findings[0].effect == "scale_nonlinearity"
    # the first candidate stands for "an earlier term"; every later one is within it
    calls = []

    def within(pb, terms, term, coef):
        calls.append(term.effect_id)
        return 0.0, "turntable_geometry"

    monkeypatch.setattr(diagnose_mod, "_outside_earlier_terms", within)
    d = diagnose(rec, n_null=30, seed=1)
    assert calls and any("rejected_within" in s for s in d.stage_log)
    assert not any(f.effect == "scale_nonlinearity" for f in d.findings)
    (f,) = [f for f in d.findings if f.effect == "unexplained"]
    assert "scale_nonlinearity" in f.where["candidates"]
    assert "cannot tell scale_nonlinearity" in f.explanation
    assert "from turntable_geometry" in f.explanation
    assert "100.0 % of its fit beyond the base model" in f.explanation
    assert d.mismatch is True


def test_each_reason_names_only_its_own_effects():
    """One candidate within an earlier term and one held-out data did not confirm: the
    'cannot tell … from' sentence names the first only, the held-out one the second."""
    from calibration.discrepancy import not_confirmed as nc

    X = np.zeros((3, 1))
    held = nc.NotConfirmed("bias_drift", 1e-4, 10.0, 10.5, ("x",), {}, X)
    inside = nc.NotConfirmed("scale_nonlinearity", 1e-6, 10.0, 9.0, ("z",), {}, X,
                             within="turntable_geometry", share_outside=0.02)
    text = nc._sentence([inside, held], ["scale_nonlinearity", "bias_drift"])
    within_part, heldout_part = text.split("neither named nor modelled.", 1)
    assert "cannot tell scale_nonlinearity from turntable_geometry" in within_part
    assert "bias_drift" not in within_part
    assert "bias_drift (p_family" in heldout_part and "scale_nonlinearity" not in heldout_part


def test_a_term_judged_in_noise_units_is_reported_in_the_units_that_decided():
    """A turn or cross-coupling term is judged held out in units of the readings' noise
    (``shrunk_heldout``): its µg figures can fall while that rises. The sentence says the
    figures that decided, not "9.894 → 9.891 µg: does not lower the error" (issue 22, a
    300 k-reading cross_coupling recording)."""
    from calibration.discrepancy import not_confirmed as nc

    X = np.zeros((3, 1))
    turn = nc.NotConfirmed("cross_coupling", 2e-136, 9.894, 9.891, ("x",), {}, X,
                           heldout_noise_units=(1.0012, 1.0019))
    text = nc._sentence([turn], ["cross_coupling"])
    assert ("held-out RMS in units of the readings' noise, as its test judges it, "
            "1.0012 → 1.0019 with its term; in µg 9.894 → 9.891 µg") in text
    assert "does not lower the error" in text
    plain = nc._sentence([nc.NotConfirmed("bias_drift", 1e-4, 10.0, 10.5, ("x",), {}, X)],
                         ["bias_drift"])
    assert "held-out RMS 10 → 10.5 µg with its term" in plain
    assert "units of the readings' noise" not in plain
