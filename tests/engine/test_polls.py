"""The soak's and the ramp's polls answered without a device (service/engine/polls.py)."""

from __future__ import annotations

import pytest

from drivers.protocols import ChamberStatus
from service.engine import polls
from service.engine.rate_gain import Probe


def test_a_settled_die_far_from_the_pv_is_a_misread_chamber_an_approaching_one_a_lag() -> None:
    track, why = polls.die_against_chamber(None, 0.0, [20.0, 20.1], 2.0)
    assert why is None and track == (0.0, 20.05)  # the first reading only starts the track
    _, why = polls.die_against_chamber(track, 600.0, [20.0, 20.1], 2.0)
    assert why is not None and why.startswith("the chamber reads 2.0 °C while the sensors' "
                                              "dies read 20.1 °C")
    assert "+0.00 °C/min" in why
    # 18 °C away, approaching at 1 °C/min: a lag of 18 min (< 1 h), not a mis-read
    track, why = polls.die_against_chamber((0.0, 21.0), 60.0, [20.0], 2.0)
    assert why is None and track == (60.0, 20.0)
    # no temperature channel: nothing said, the track kept
    assert polls.die_against_chamber(track, 120.0, [float("nan")], 2.0) == (track, None)


def test_a_die_behind_a_moving_air_is_a_lag_a_misread_steady_chamber_is_not() -> None:
    """A ramp campaign's chamber never stops. At a turn of the ramp a die behind a fixture
    still rises while the air falls away (7.8 °C apart, the die at −0.12 °C/min, as a
    loaded 3000× run of the browser test saw): with the air moving at 1 °C/min that gap is
    lag. The same gap with the air standing still is a chamber read wrong; a ×10 scale is
    refused even on a moving air."""
    before = (0.0, 38.0)
    _, why = polls.die_against_chamber(before, 60.0, [37.88], 30.1)
    assert why is not None and "the chamber reads 30.1 °C" in why
    _, why = polls.die_against_chamber(before, 60.0, [37.88], 30.1, pv_before=(0.0, 31.1))
    assert why is None
    _, why = polls.die_against_chamber(before, 60.0, [37.88], 301.0, pv_before=(0.0, 302.0))
    assert why is not None and "the chamber reads 301.0 °C" in why


def test_a_ramp_arrives_with_setpoints_and_pv_and_is_bounded_by_twice_its_nominal_time() -> None:
    at = ChamberStatus(39.9, 40.0, 40.0, 1.0, True)
    assert polls.chamber_arrived(at, 40.0, tol_c=0.2)
    assert not polls.chamber_arrived(ChamberStatus(39.9, 40.0, 39.0, 1.0, True), 40.0, 0.2)
    # 20 °C at 2 °C/min is 10 min nominal: 20 min, plus a max soak of 1 h
    assert polls.ramp_limit_s(20.0 - 40.0, 2.0, 3600.0)[0] == pytest.approx(1200.0 + 3600.0)
    assert polls.active_s(1000.0, 100.0, held_total_s=500.0, held0_s=200.0) == 600.0


def test_a_soak_round_asks_the_die_that_waited_first_and_ends_on_the_slowest() -> None:
    from service.engine.stability import StabilityConfig

    cfg = StabilityConfig(policy="fixed", soak_s=600.0)
    soak = polls.SoakState(cfg, sweep_s=100.0, start_s=0.0, held0_s=0.0,
                           dies={"A": [Probe(0.0, 0.0, 20.0, (0.0, 0.0, 1.0))], "B": []})
    asked: list[str] = []

    def gain(serial: str, _probes: list[Probe]) -> float | None:
        asked.append(serial)
        return None

    d = polls.decide_round(soak, 300.0, 20.0, ["A", "B"], gain, n_positions=6, edge=False,
                           order_repeats=1)
    assert not d.stable and d.reason == "fixed_soak_waiting" and soak.waiting_on == "A"
    assert sorted(asked) == ["A", "B"]
    d = polls.decide_round(soak, 650.0, 20.0, ["B"], gain, n_positions=6, edge=False,
                           order_repeats=1)  # A dropped meanwhile: B alone decides
    assert d.stable and soak.decision is d and set(soak.gains) == {"B"}
