"""The ETA of a step campaign (``ramp_c_per_min: 0``): the ramps are predicted at the
chamber's moving rate (drivers/ramp_rule.py), undetermined when that rate is not known,
and replaced by the measured mean once a ramp has been timed."""

from __future__ import annotations

from typing import Any

import pytest

from drivers.ramp_rule import RampControl, moving_rate_c_per_min
from service.engine.progress import EtaModel
from service.engine.spec import parse_spec

# Three setpoints 20 °C apart, six positions, a 30 min soak.
BASE: dict[str, Any] = {"setpoints_c": [-10.0, 10.0, 30.0], "soak_min": 30, "positions": "six",
                        "samples_per_position": 20}
STEPS_CTRL = RampControl("map csz-ezt-430i", False, "no ramp register", 4.0)


def _spec(ramp_c_per_min: float) -> Any:
    return parse_spec({**BASE, "ramp_c_per_min": ramp_c_per_min})


def test_a_step_is_predicted_at_the_chambers_own_rate() -> None:
    spec = _spec(0)
    rate = moving_rate_c_per_min(STEPS_CTRL, spec.ramp_c_per_min)
    eta = EtaModel.for_spec(spec, 6, rate_c_per_min=rate)
    # 20 °C at the chamber's own 4 °C/min is 5 min, not 20 / 0.05 min = 24,000 s.
    assert eta.ramp_s == pytest.approx(300.0)
    # At step 0, ramping: 18 positions × 15 s + this step's soak + 2 × (ramp + soak).
    soak_s = eta.soak_s  # the spec's policy's expected soak
    assert eta.eta_s(0, "ramp") == pytest.approx(18 * 15.0 + 3 * soak_s + 2 * 300.0)


def test_a_step_at_an_unknown_rate_has_no_eta_until_a_ramp_is_measured() -> None:
    eta = EtaModel.for_spec(_spec(0), 6, rate_c_per_min=None)
    assert eta.ramp_s is None
    assert eta.eta_s(0, "ramp") is None  # two ramps ahead, time unknown: no number
    eta.ramp_done(420.0)
    assert eta.ramp_s == 420.0
    assert eta.eta_s(0, "ramp") == pytest.approx(18 * 15.0 + 3 * eta.soak_s + 2 * 420.0)
    # On the last step no ramp is left: the ETA is known even without a rate.
    late = EtaModel.for_spec(_spec(0), 6, n_done=12)
    assert late.eta_s(2, "soak", soak_remaining_s=600.0) == pytest.approx(6 * 15.0 + 600.0)


def test_measured_ramps_replace_the_prediction_as_soaks_do() -> None:
    eta = EtaModel.for_spec(_spec(0), 6, rate_c_per_min=4.0)
    eta.ramp_done(200.0)
    eta.ramp_done(400.0)
    assert eta.ramp_s == pytest.approx(300.0)
    eta.ramp_done(900.0)
    assert eta.ramp_s == pytest.approx(500.0)


def test_a_commanded_ramp_is_predicted_exactly_as_before() -> None:
    """ramp_c_per_min > 0 without a rate: the spec's rate (and its 0.05 °C/min floor), bit
    for bit; the rule's moving rate on a controlled chamber is the same number."""
    for ramp in (1.0, 2.5, 0.01):
        spec = _spec(ramp)
        legacy_s = 20.0 / max(ramp, 0.05) * 60.0
        assert EtaModel.for_spec(spec, 6).ramp_s == legacy_s
        ctrl = RampControl("map eurotherm-3216", True, "n/a", None)
        rate = moving_rate_c_per_min(ctrl, ramp)
        assert rate == ramp
        if ramp >= 0.05:
            assert EtaModel.for_spec(spec, 6, rate_c_per_min=rate).ramp_s == legacy_s


def test_a_ramps_time_limit_uses_the_moving_rate_and_states_its_basis() -> None:
    from service.engine.polls import ramp_limit_s
    from service.engine.progress import chamber_moving_rate_c_per_min

    class Stepping:  # a driver whose chamber steps at its own 4 °C/min
        ramp_control = STEPS_CTRL

    rate = chamber_moving_rate_c_per_min(Stepping(), 0.0)
    assert rate == 4.0
    limit_s, basis = ramp_limit_s(-20.0, rate, 7200.0)
    assert limit_s == pytest.approx(20.0 / 4.0 * 60.0 * 2.0 + 7200.0)  # 600 s + the soak
    assert basis == "twice 20.0 °C at 4 °C/min + the longest soak"
    # Unknown (a driver without ramp_control, a step): a stated bound, not a silent one.
    assert chamber_moving_rate_c_per_min(object(), 0.0) is None
    assert chamber_moving_rate_c_per_min(object(), 2.0) == 2.0
    limit_s, basis = ramp_limit_s(20.0, None, 7200.0)
    assert limit_s == pytest.approx(20.0 / 0.05 * 60.0 * 2.0 + 7200.0)
    assert basis == ("the chamber's rate is not known: twice 20.0 °C at 0.05 °C/min, the "
                     "slowest the engine waits for + the longest soak")
