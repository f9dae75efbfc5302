"""A glitch of the temperature channel on one reading is not an ``outlier`` (issue 22).

The generator sets the *recorded* temperature of one reading off by δ; the output follows
the die. The per-reading test flags the residual the model leaves at the wrong temperature;
``channel_glitch.check_reading`` then asks what the data show: the recorded temperature
against its plateau neighbours, and the residual along the model's own ∂output/∂T with one
scalar δ. A glitch is named ``temperature_sensor`` with δ ± sd; a shock at a normal
temperature stays ``outlier``; where the temperature cannot decide, both are candidates.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

from calibration.discrepancy import diagnose
from calibration.discrepancy.effects import channel_glitch as cg
from calibration.schedules import table1
from simulators import effects as fx
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

SEED = 3
ROW = 5 * 24 + 7  # Table 1 (24 positions), plateau 5, position 7
GLITCH_C = 4.0  # about twice what this sensor's model shows at one reading


def _diagnose(effect, schedule=None):
    truth = SensorTruth.adxl355_typical(seed=SEED, effects=[effect])
    rec = simulate_campaign(truth, schedule=schedule, seed=100 + SEED)
    return diagnose(rec, n_null=200, seed=SEED)


def test_a_glitch_of_the_channel_is_named_temperature_sensor_with_its_size():
    d = _diagnose(fx.TemperatureSensor(glitch_c=GLITCH_C, glitch_rows=(ROW,)))
    assert [f.effect for f in d.findings] == ["temperature_sensor"]
    (f,) = d.findings
    assert f.rows == [ROW]
    delta, sd = f.parameters["glitch_c"], f.parameter_sd["glitch_c"]
    assert sd < GLITCH_C / 10  # a size, not a sign
    assert abs(delta - GLITCH_C) <= 3 * sd
    # the channel's own departure from its neighbours is the glitch, to its scatter
    assert abs(f.parameters["channel_departure_c"] - GLITCH_C) <= 3 * max(
        f.parameter_sd["channel_departure_c"], 0.01)
    assert "excluded from the kept model" in f.explanation
    assert {"outlier"} == {c["effect"] for c in f.confusers}
    (twin,) = fx.to_truth_effects(d.to_dict()["findings"])  # a twin holds the glitch
    assert (twin.glitch_rows, twin.glitch_c) == ((ROW,), delta)


def test_a_shock_at_a_normal_temperature_stays_outlier():
    d = _diagnose(fx.Outlier(size_g=np.array([60e-6, -40e-6, 50e-6]), rows=(ROW,)))
    assert [f.effect for f in d.findings] == ["outlier"]
    assert d.findings[0].rows == [ROW]


def test_without_neighbours_to_judge_the_temperature_a_glitch_is_not_separable():
    """Four positions per plateau: three neighbours cannot tell whether the recorded
    temperature departs, and the residual along ∂output/∂T fits a glitch and a shock alike."""
    sch = table1()[[0, 2, 6, 8]]
    d = _diagnose(fx.TemperatureSensor(glitch_c=GLITCH_C, glitch_rows=(5 * 4 + 2,)),
                  schedule=sch)
    (f,) = [f for f in d.findings if f.rows]
    assert f.effect == "not_identifiable"
    assert f.where["candidates"] == ["temperature_sensor", "outlier"]
    assert {"temperature_sensor", "outlier"} <= {n["effect"] for n in d.not_identifiable}
    assert "fewer than" in f.explanation


def _dep(d_c: float, sd_c: float) -> cg.Departure:
    return cg.Departure(d_c, sd_c, sd_c / 3, 8)


def test_a_flat_thermal_model_cannot_tell_the_shape():
    """The channel departs by 2 °C beyond doubt and the output agrees with it, but on a model
    this flat in T (σ_δ = 1 °C) 2 °C alone would not move the output beyond its noise: a
    glitch and a shock are not separable. The same numbers on a steep model are a glitch;
    a normal temperature excludes the δ the output would need: an outlier."""
    alpha = 0.01
    assert norm.isf(alpha / 2) * 1.0 > 2.0
    flat, _ = cg.decide(_dep(2.0, 0.05), 4.4, 1.0, -0.3, alpha)
    steep, _ = cg.decide(_dep(2.0, 0.05), 2.2, 0.1, -0.3, alpha)
    shock, _ = cg.decide(_dep(0.02, 0.05), 2.2, 0.1, -0.3, alpha)
    beside, _ = cg.decide(_dep(2.0, 0.05), 2.2, 0.1, -3.0, alpha)  # residual beside ∂f/∂T
    assert (flat, steep, shock, beside) == (cg.NOT_SEPARABLE, cg.GLITCH, cg.OUTLIER,
                                            cg.OUTLIER)


def test_the_departure_is_read_against_the_plateau_neighbours():
    """A line through a creeping plateau: the glitched reading departs by its δ, a normal
    reading by its noise, and a plateau of four readings is too few to judge."""
    rng = np.random.default_rng(1)
    n = 24

    class Ctx:
        temperature_source = "sensor_c"
        t_s = np.arange(n) * 60.0
        steps = np.repeat([0, 1], n // 2)
        step_ids = [0, 1]
        temp_c = 20.0 + 0.002 * t_s + 0.01 * rng.standard_normal(n)

    Ctx.n = n
    Ctx.temp_c[5] += 0.8
    glitched = cg.temperature_departure(Ctx, 5, set())
    normal = cg.temperature_departure(Ctx, 7, set())
    assert abs(glitched.departure_c - 0.8) < 4 * glitched.sd_c
    assert abs(glitched.departure_c) > 10 * glitched.sd_c
    assert abs(normal.departure_c) < 4 * normal.sd_c
    Ctx.steps = np.repeat(np.arange(6), 4)
    Ctx.step_ids = list(range(6))
    assert cg.temperature_departure(Ctx, 5, set()) is None


def test_in_norm_mode_a_large_glitch_is_named_by_the_secant():
    """Without references only |f| is seen: no dof beside δ, and a 10 °C glitch on the cubic
    is far from the tangent's linearisation (the tangent called it ``outlier``)."""
    from dataclasses import replace

    for effect, named in ((fx.TemperatureSensor(glitch_c=10.0, glitch_rows=(ROW,)),
                           "temperature_sensor"),
                          (fx.Outlier(size_g=np.array([60e-6, -40e-6, 50e-6]), rows=(ROW,)),
                           "outlier")):
        rec = simulate_campaign(SensorTruth.adxl355_typical(seed=SEED, effects=[effect]),
                                seed=100 + SEED)
        rec = replace(rec, columns={k: v for k, v in rec.columns.items()
                                    if not k.startswith("ref_")})
        d = diagnose(rec, n_null=200, seed=SEED)
        assert d.mode == "norm"
        assert [(f.effect, f.rows) for f in d.findings] == [(named, [ROW])]
        if named == "temperature_sensor":
            f = d.findings[0]
            assert abs(f.parameters["glitch_c"] - 10.0) <= 3 * f.parameter_sd["glitch_c"]
