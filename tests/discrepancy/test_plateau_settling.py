"""A rate term must hold on every plateau and beat a settling after each plateau's start
(issue 22; calibration/discrepancy/plateau_settling.py and
``temperature_rate.gain_differs_between_plateaus``).

Outside-catalogue structure that fades after a plateau starts (a fixture relaxing after the
moves, a chamber cycle in phase with a plateau's warm-up) was named ``temperature_rate``.
Two physics checks now ask what a rate effect predicts and a settling does not: one gain on
every plateau, and a size and sign that follow the die's rate plateau by plateau. A true
rate effect on an up-down campaign (steps of both signs) passes both.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from calibration.discrepancy.by_fit import MARGIN
from calibration.discrepancy.diagnose import Term, _design
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.base import per_axis
from calibration.discrepancy.effects.structure import extend, whitened
from calibration.discrepancy.effects.temperature_rate import gain_differs_between_plateaus
from calibration.discrepancy.plateau_settling import (
    TAUS_S,
    settling_alike,
    since_plateau_start_s,
)
from calibration.discrepancy.problem import build_problem
from calibration.discrepancy.stats import orthonormal_basis
from calibration.discrepancy.temperature_jump import lead_over_rivals
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 20)]
UP_DOWN = [float(t) for t in list(range(-40, 61, 20)) + list(range(50, -41, -20))]
ALPHA = 0.005
RATE = fx.TemperatureRate(np.array([4e-3, -3e-3, 2e-3]))  # g per °C/s of the die


@dataclass
class SettlingAfterStart:
    """Outside the catalogue: every plateau's output relaxes by ``size_g`` on x and z with
    ``tau_s`` after its first reading (a fixture relaxing after the plateau's moves).
    ``only_step``: on that plateau alone."""

    size_g: float
    tau_s: float = 300.0
    only_step: int | None = None
    effect_id: str = "settling"

    def raw_delta_g(self, ctx, truth, rng):
        out = np.zeros((ctx.t_s.size, 3))
        for s in np.unique(ctx.step):
            m = ctx.step == s
            if self.only_step is not None and s != self.only_step:
                continue
            decay = self.size_g * np.exp(-(ctx.t_s[m] - ctx.t_s[m].min()) / self.tau_s)
            out[m, 0], out[m, 2] = decay, -decay
        return out

    def temperature_delta_c(self, ctx, rng):
        return np.zeros(ctx.t_s.size)


def _campaign(setpoints, effects, seed=11):
    truth = SensorTruth.adxl355_typical(seed=seed, effects=effects)
    return simulate_campaign(truth, setpoints, seed=100 + seed, soak_min=20.0)


def _rate_term(pb):
    eff = BY_ID["temperature_rate"]
    return Term("temperature_rate", float("nan"), pb.lift(eff.regressors(pb.ctx, float("nan"))))


def _lead(rec) -> float:
    pb = build_problem(rec)
    ctx = pb.ctx
    since = since_plateau_start_s(ctx)
    rivals = {tau: per_axis(ctx, np.exp(-since / tau)) for tau in TAUS_S}
    term = _rate_term(pb)
    lead, _ = lead_over_rivals(pb, [term], term, False, rivals, _design)
    return lead


def test_since_plateau_start_is_zero_at_each_plateaus_first_reading():
    rec = _campaign(ONE_WAY, [])
    ctx = build_problem(rec).ctx
    since = since_plateau_start_s(ctx)
    for s in ctx.step_ids:
        m = ctx.steps == s
        assert since[m].min() == 0.0 and np.all(np.diff(since[m][np.argsort(ctx.t_s[m])]) >= 0)


def test_a_settling_after_each_plateaus_start_is_fitted_as_well_as_a_rate():
    lead = _lead(_campaign(ONE_WAY, [SettlingAfterStart(40e-6)]))
    assert lead < MARGIN, lead


def test_a_true_rate_on_an_up_down_campaign_out_fits_a_settling():
    lead = _lead(_campaign(UP_DOWN, [RATE]))
    assert lead >= MARGIN, lead


def _finding():
    from calibration.discrepancy.diagnose import Finding

    return Finding(effect="temperature_rate", axes=["x", "z"], where={"steps": [0]}, explanation="",
                   parameters={"k": 1.0}, parameter_sd={"k": 0.1}, rmse_before_ug=1.0,
                   rmse_after_ug=1.0, heldout_rmse_before_ug=1.0, heldout_rmse_after_ug=1.0,
                   p_value=1e-6, test="t", term_effect="temperature_rate")


def test_settling_alike_withholds_the_rate_name_and_lists_both_candidates():
    pb = build_problem(_campaign(ONE_WAY, [SettlingAfterStart(40e-6)]))
    term = _rate_term(pb)
    not_ident: dict = {}
    f = settling_alike(pb, [term], _finding(), ALPHA, not_ident, [], _design)
    assert f.effect == "not_identifiable"
    assert f.where["candidates"][0] == "temperature_rate"
    assert "settling after each plateau's start" in f.where["candidates"][1]
    assert "temperature_rate" in not_ident and not f.parameters


def test_settling_alike_leaves_other_names_alone():
    pb = build_problem(_campaign(ONE_WAY, [SettlingAfterStart(40e-6)]))
    f = replace(_finding(), effect="bias_drift", term_effect="bias_drift")
    assert settling_alike(pb, [_rate_term(pb)], f, ALPHA, {}, [], _design) is f


def _with_rate(rec):
    pb = build_problem(rec)
    U = orthonormal_basis(pb.X0 * pb.w[:, None])
    yw = pb.y * pb.w
    U, e = extend(U, yw - U @ (U.T @ yw), whitened(pb, BY_ID["temperature_rate"].regressors(
        pb.ctx, float("nan"))))
    return pb, U, e


def test_a_decay_on_one_plateau_is_not_one_rate_gain_on_every_plateau():
    pb, U, e = _with_rate(_campaign(UP_DOWN, [SettlingAfterStart(60e-6, only_step=3)]))
    found = gain_differs_between_plateaus(pb, U, e, ["x", "z"], ALPHA)
    assert found is not None
    assert 3 in found["steps"] and found["kind"] == "time"
    assert found["log10_p"] < np.log10(ALPHA)


def test_a_true_rate_has_one_gain_on_every_plateau():
    for seed in (11, 12, 13):
        pb, U, e = _with_rate(_campaign(UP_DOWN, [RATE], seed=seed))
        assert gain_differs_between_plateaus(pb, U, e, ["x", "y", "z"], ALPHA) is None, seed
