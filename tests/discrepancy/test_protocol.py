"""What a recording's protocol can separate, and findings that say only that (issue 10)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calibration.discrepancy import diagnose
from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.extensions import extension_specs
from calibration.discrepancy.protocol import assess, position_order_kind
from calibration.discrepancy.protocol_order import position_order
from calibration.discrepancy.report import protocol_lines
from calibration.recording import Recording
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]
UP_DOWN = [-40.0, 0.0, 40.0, 60.0, 20.0, -20.0]


def ctx_of(step_temps: list[float], order: np.ndarray | None = None, source: str = "chamber_c",
           n_pos: int = 6, oblique: bool = False) -> DesignContext:
    """A context of len(step_temps) plateaus, n_pos positions each, one reading a minute."""
    n_steps = len(step_temps)
    order = position_order(n_pos, n_steps, "fixed") if order is None else order
    steps = np.repeat(np.arange(n_steps), n_pos)
    positions = order.ravel()
    t = np.arange(steps.size, dtype=float) * 60.0
    temps = np.repeat(np.asarray(step_temps, float), n_pos)
    a = np.zeros((steps.size, 3))
    a[np.arange(steps.size), positions % 3] = 1.0
    if oblique:
        a[positions == 0] = [np.sqrt(0.5), np.sqrt(0.5), 0.0]
    n = steps.size
    return DesignContext(
        mode="reference", t_s=t, temp_c=temps if source != "none" else np.zeros(n),
        temperature_source=source, has_chamber_c=source == "chamber_c",
        has_sensor_c=source == "sensor_c", steps=steps, positions=positions,
        step_temp_c={k: (step_temps[k] if source != "none" else 0.0) for k in range(n_steps)},
        direction=np.zeros(n), time_since_step_s=np.zeros(n),
        input_g=a, sd_g=None, draw_dtemp_g_per_c=np.zeros((n, 3)), session=None)


def groups(pr) -> dict[frozenset[str], object]:
    return {frozenset(c.effects): c for c in pr.not_separable}


@pytest.mark.parametrize(("scheme", "seen"),
                         [("fixed", "fixed"), ("random", "varied"), ("balanced", "balanced")])
def test_position_order_is_read_from_time_within_steps(scheme, seen):
    order = position_order(6, 6, scheme, seed=3)
    ctx = ctx_of([0.0] * 6, order)
    assert position_order_kind(ctx.steps, ctx.positions, ctx.t_s) == seen
    assert position_order_kind(ctx.steps[:6], ctx.positions[:6], ctx.t_s[:6]) == "one plateau"


def test_a_least_travel_order_is_called_varied_not_random():
    """The engine's default order: each plateau starts where the last ended (not random)."""
    from calibration.position_order import step_orders
    from calibration.schedules import cube14
    from drivers.geometry import angles_for_references

    travel = np.array(step_orders(angles_for_references(cube14()), 6, "travel"))
    ctx = ctx_of(UP_DOWN, travel, n_pos=14)
    pr = assess(ctx)
    assert pr.position_order == "varied"
    line = protocol_lines(pr.to_json())[0]
    assert "position order varied (from t_s within steps)" in line and "random" not in line


def test_a_visit_column_overrides_the_time_order():
    """Readings written in position order, but visited in a balanced order: the visit decides."""
    order = position_order(6, 6, "balanced", seed=1)
    steps = np.repeat(np.arange(6), 6)
    positions = np.tile(np.arange(6), 6)  # rows sorted by position within each step
    t = np.arange(36, dtype=float)
    visit = np.concatenate([np.argsort(row) for row in order]).astype(float)  # slot of each
    assert position_order_kind(steps, positions, t) == "fixed"
    assert position_order_kind(steps, positions, t, visit) == "balanced"


def test_fixed_order_confuses_time_within_plateau_with_orientation_only_when_fixed():
    fixed = assess(ctx_of(UP_DOWN, oblique=True))
    c = groups(fixed)[frozenset({"self_heating", "bias_drift", "scale_nonlinearity",
                                 "cross_coupling"})]
    assert c.alternatives("scale_nonlinearity") == ["self_heating", "bias_drift"]
    assert "scale_nonlinearity" not in c.alternatives("cross_coupling")
    assert not c.withhold  # the nonlinearity keeps its name; the warm-up is listed
    balanced = assess(ctx_of(UP_DOWN, position_order(6, 6, "balanced", seed=2), oblique=True))
    assert balanced.position_order == "balanced"
    assert not any("scale_nonlinearity" in c.effects for c in balanced.not_separable)


def test_one_way_staircase_withholds_rate_against_session_jump_when_both_testable():
    testable = {e: True for e in ("temperature_rate", "session_offset", "outlier")}
    pr = assess(ctx_of(ONE_WAY), identifiable=testable)
    assert pr.temperature == "one way"
    c = pr.withheld_with("temperature_rate")
    assert c is not None and c is pr.withheld_with("session_offset")
    assert pr.separable == ("outlier",)
    # At dT/dt ≈ 0 no rate term can be in the data: the jump is the only candidate.
    pr0 = assess(ctx_of(ONE_WAY), identifiable={**testable, "temperature_rate": False})
    assert pr0.withheld_with("session_offset") is None
    # Plateaus approached from both sides separate a rate from a jump.
    assert assess(ctx_of(UP_DOWN), identifiable=testable).withheld_with("temperature_rate") \
        is None


def test_one_plateau_confuses_time_and_orientation_only_when_each_position_is_read_once():
    def time_vs_orientation(pr) -> bool:
        return any({"self_heating", "scale_nonlinearity"} <= set(c.effects)
                   for c in pr.not_separable)

    assert time_vs_orientation(assess(ctx_of([0.0], source="none")))
    twice = assess(ctx_of([0.0], np.array([[0, 1, 2, 3, 4, 5, 5, 4, 3, 2, 1, 0]]), n_pos=12,
                          source="none"))
    assert twice.position_order == "one plateau"
    assert not time_vs_orientation(twice)


def test_no_temperature_column_separates_nothing_thermal():
    pr = assess(ctx_of([0.0], source="none"))
    assert pr.temperature == "none" and pr.position_order == "one plateau"
    thermal = next(c for c in pr.not_separable if "thermal_lag" in c.effects)
    assert {"thermal_hysteresis", "temperature_rate", "self_heating"} <= set(thermal.effects)
    assert "bias_drift" in thermal.effects and "temperature" in thermal.why
    assert "thermal_lag" in thermal.alternatives("bias_drift")


def test_rate_confused_with_session_jump_is_reported_not_identifiable():
    """One-way staircase, plateaus 0–3 still settling (0.2 °C/min): a rate term on them is a
    jump after plateau 3; both are significant, so neither is named."""
    truth = SensorTruth.adxl355_typical(seed=5)
    rec = simulate_campaign(truth, ONE_WAY, soak_min=20.0, seed=6,
                            temperature_columns=("chamber_c",),
                            physics=replace(RigPhysics(), die_tau_s=30.0))
    cols = dict(rec.columns)
    t, st = cols["t_s"], cols["step"]
    slope = np.where(st <= 3, 0.2, 0.02)  # °C/min
    first = np.array([t[st == s].min() for s in st])
    cols["chamber_c"] = np.asarray(cols["chamber_c"], float) + slope * (t - first) / 60.0
    for a, k in zip(("ax", "ay", "az"), (200e-6, -150e-6, 100e-6), strict=True):
        cols[a] = np.asarray(cols[a], float) + k * slope  # g per °C/min
    d = diagnose(Recording.from_columns(cols), n_null=30, seed=0)
    names = [f.effect for f in d.findings]
    assert "temperature_rate" not in names and "session_offset" not in names
    f = d.findings[names.index("not_identifiable")]
    assert set(f.where["candidates"]) == {"temperature_rate", "session_offset"}
    assert "temperature_rate" in f.explanation and "session_offset" in f.explanation
    assert f.parameters == {} and f.heldout_rmse_after_ug < f.heldout_rmse_before_ug
    listed = {n["effect"]: n["why"] for n in d.not_identifiable}
    assert "session_offset" in listed["temperature_rate"]
    assert not any(s["kind"].endswith("not_identifiable") for s in extension_specs(d))
    block = d.to_dict()["protocol"]
    assert block["temperature"] == "one way" and block["position_order"] == "fixed"
    withheld = [c for c in block["not_separable"] if c["finding_withheld"]]
    assert withheld and "temperature_rate" in withheld[0]["effects"]
    assert "Protocol: one way over 11 plateau(s)" in d.report()


# --- explanations say only what the data can show -----------------------------
def test_drift_sentence_claims_no_temperature_comparison_without_a_temperature():
    eff = BY_ID["bias_drift"]
    p, s = {"rate_x_ug_per_h": 4.0}, {"rate_x_ug_per_h": 0.5}
    with_t = eff.sentence(p, s, ["x"], ctx_of([0.0, 20.0]))
    without = eff.sentence(p, s, ["x"], ctx_of([0.0], source="none"))
    assert "not with temperature" in with_t
    assert "not with temperature" not in without and "no temperature is recorded" in without


def test_hysteresis_sentence_follows_the_sign_of_h():
    eff = BY_ID["thermal_hysteresis"]
    sd = {"h_x_ug": 2.0, "h_y_ug": 2.0}
    assert "reads higher after heating" in eff.sentence({"h_x_ug": 20.0, "h_y_ug": 9.0}, sd,
                                                        ["x", "y"])
    assert "reads lower after heating" in eff.sentence({"h_x_ug": -20.0, "h_y_ug": -9.0}, sd,
                                                       ["x", "y"])
    assert "reads differently" in eff.sentence({"h_x_ug": 20.0, "h_y_ug": -9.0}, sd, ["x", "y"])


def test_lag_sentence_says_the_ramp_is_assumed():
    text = BY_ID["thermal_lag"].sentence({"tau_s": 900.0, "amplitude": 1.0}, {"tau_s": 30.0},
                                         ["x", "y", "z"])
    assert "assumed 2 °C/min ramp" in text


def test_diagnosed_drift_without_a_temperature_does_not_claim_one():
    """Four plateaus, no temperature column: the drift is named, the sentence makes no
    temperature comparison, and the protocol says nothing thermal is separable."""
    from simulators import effects as E  # noqa: N812

    truth = SensorTruth.adxl355_typical(
        seed=5, effects=[E.BiasDrift(rate_g_per_h=np.array([0.0, 0.0, 20e-6]))])
    rec = simulate_campaign(truth, [25.0] * 4, seed=6, temperature_columns=("chamber_c",))
    cols = dict(rec.columns)
    cols["chamber_c"] = np.full(len(rec), np.nan)
    d = diagnose(Recording.from_columns(cols), n_null=30, seed=0)
    f = d.findings[0]
    assert f.effect == "bias_drift" and f.axes == ["z"]
    assert "not with temperature" not in f.explanation
    assert "no temperature is recorded" in f.explanation
    block = d.to_dict()["protocol"]
    assert block["temperature"] == "none"
    assert not {"thermal_lag", "thermal_hysteresis"} & set(block["separable"])


def identifiable_in(ctx: DesignContext) -> dict[str, bool]:
    """What ``diagnose`` passes to ``assess``: each catalogue effect's own identifiability."""
    return {e.effect_id: e.identifiable(ctx)[0] for e in BY_ID.values()}


def test_one_way_settled_staircase_lists_the_power_cycle_as_not_separable():
    """Issue 22: settled plateaus (no rate term in the data) on a one-way staircase with no
    session column: a power cycle between plateaus is a jump where the temperature crosses
    a T*; the protocol block says so, with the reason and the experiment, and no longer
    calls session_offset separable. Nothing is withheld on it (findings are unchanged)."""
    ctx = ctx_of(ONE_WAY)
    testable = identifiable_in(ctx)
    assert testable["session_offset"] and not testable["temperature_rate"]  # settled
    pr = assess(ctx, identifiable=testable)
    entry = next(c for c in pr.not_separable if "session_offset" in c.effects)
    assert not entry.withhold and entry.alternatives("session_offset") == []
    assert any("T*" in o and "outside the catalogue" in o for o in entry.outside)
    assert "one-way staircase" in entry.why and "revisit a temperature" in entry.experiment
    assert "session_offset" not in pr.separable
    js = next(c for c in pr.to_json()["not_separable"] if "session_offset" in c["effects"])
    assert js["outside_catalogue"] == list(entry.outside) and js["experiment"]
    line = next(x for x in protocol_lines(pr.to_json()) if "session_offset" in x)
    assert "cannot separate session_offset from a jump of the output" in line
    assert "to separate them: revisit a temperature" in line


def test_power_cycle_is_not_listed_where_the_protocol_separates_it():
    """Plateaus in a non-monotonic temperature order, a session column, or one temperature
    held over every plateau: a power cycle is not a jump at a temperature there."""
    up_down = ctx_of(UP_DOWN)
    logged = replace(ctx_of(ONE_WAY), session=np.repeat([0, 1], 33))
    held = ctx_of([20.0] * 6)
    for ctx in (up_down, logged, held):
        pr = assess(ctx, identifiable=identifiable_in(ctx))
        assert not any("session_offset" in c.effects for c in pr.not_separable), ctx
        assert "session_offset" in pr.separable
