"""One rule for chambers that cannot control their ramp (drivers/ramp_rule.py), the same
over Modbus (a map without a ramp register) and over ESPEC's ASCII protocol: 0 is a step
and writes nothing, a rate at or above the chamber's own is that step too, a slower one is
refused naming the fix; 0 on a map whose ramp register's 0 is unstated is refused naming
the map, and nothing is written."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest

from drivers.chamber import ModbusChamber
from drivers.clock import VirtualClock
from drivers.espec_chamber import EspecChamber, EspecSettings
from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.ramp_rule import RampControl, ramp_method_refusal, ramp_refusal
from drivers.registermaps import load_chamber_map
from simulators.chamber_sim import ChamberPhysics
from simulators.espec_sim import EspecController, start_espec_server
from simulators.rig import start_sim_rig

# The one shape of the refusal, whichever protocol: what, why, the chamber's own rate, the fix.
SHAPE = re.compile(
    r"ramp rate 2 °C/min cannot be commanded: (?P<who>.+) has no static ramp \((?P<why>.+)\) "
    r"and steps to each setpoint at the chamber's own rate \(up to 4 °C/min, (?P<key>.+)\); "
    r"run the campaign with ramp_c_per_min = 0 \(step\) or ≥ 4$")


def _counting_writes(chamber: ModbusChamber) -> list[Any]:
    """Every register write the driver sends, in order (the link is the wire's door)."""
    writes: list[Any] = []
    send = chamber.link.write_field

    async def write_field(field: Any, value: float) -> None:
        writes.append((field.address, value))
        await send(field, value)

    chamber.link.write_field = write_field  # type: ignore[method-assign]
    return writes


async def _refusal(coro: Any) -> str:
    with pytest.raises(ValueOutOfRange) as err:
        await coro
    return err.value.message


async def test_a_map_without_a_ramp_and_an_espec_follow_one_rule_with_one_message() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="csz-ezt-430i") as sim:
        ezt = ModbusChamber(ModbusLink(sim.chamber_url, clock, device="chamber"),
                            load_chamber_map("csz-ezt-430i"), max_rate_c_per_min=4.0)
        writes = _counting_writes(ezt)
        for honoured in (0.0, 4.0, 6.0):  # a step, and rates the step does not exceed
            await ezt.set_ramp_rate(honoured)
        assert writes == []  # a ramp it does not have: nothing is written
        modbus_msg = await _refusal(ezt.set_ramp_rate(2.0))
        assert writes == []
        await ezt.close()

    physics = ChamberPhysics(clock, np.random.default_rng(1), air_c=23.0, setpoint_c=23.0)
    server = await start_espec_server(EspecController(physics, None))
    espec = EspecChamber(EspecSettings(url=server.url, range_c=(-40.0, 85.0),
                                       max_rate_c_per_min=4.0), clock, timeout_s=0.5)
    try:
        for honoured in (0.0, 4.0, 6.0):
            await espec.set_ramp_rate(honoured)
        espec_msg = await _refusal(espec.set_ramp_rate(2.0))
    finally:
        await espec.close()
        await server.stop()

    m_modbus, m_espec = SHAPE.match(modbus_msg), SHAPE.match(espec_msg)
    assert m_modbus and m_espec, (modbus_msg, espec_msg)
    assert m_modbus["who"] == "map csz-ezt-430i"
    assert m_modbus["why"] == "the map lists ramp_c_per_min under absent_roles"
    assert m_modbus["key"] == "chamber.max_rate_c_per_min"
    assert m_espec["who"] == "an ESPEC P-300/SCP-220"
    assert "ramps only inside a program" in m_espec["why"]


async def test_without_a_stated_rate_only_the_step_is_accepted_and_the_map_is_named() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="watlow-f4") as sim:
        f4 = ModbusChamber(ModbusLink(sim.chamber_url, clock, device="chamber"),
                           load_chamber_map("watlow-f4"))
        await f4.set_ramp_rate(0.0)
        msg = await _refusal(f4.set_ramp_rate(50.0))
        await f4.close()
    assert msg == (
        "ramp rate 50 °C/min cannot be commanded: map watlow-f4 has no static ramp (the map "
        "lists ramp_c_per_min under absent_roles) and steps to each setpoint at the "
        "chamber's own rate, which is not stated (chamber.max_rate_c_per_min, or "
        "limits.max_ramp_c_per_min of map watlow-f4); run the campaign with "
        "ramp_c_per_min = 0 (step)")


async def test_zero_on_a_map_whose_ramp_register_may_not_mean_step_is_refused() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="eurotherm-3216") as sim:
        chamber = ModbusChamber(ModbusLink(sim.chamber_url, clock, device="chamber"),
                                load_chamber_map("eurotherm-3216"))
        await chamber.set_ramp_rate(2.0)
        writes = _counting_writes(chamber)
        msg = await _refusal(chamber.set_ramp_rate(0.0))
        assert writes == [] and sim.chamber.ramp_c_per_min == pytest.approx(2.0)
        await chamber.close()
    assert msg.startswith("ramp rate 0 °C/min (step) cannot be commanded: map eurotherm-3216 "
                          "has a ramp register and does not state that the register's 0 "
                          "means 'no ramp'")
    assert msg.endswith("run the campaign with ramp_c_per_min > 0")


def test_a_ramp_campaign_needs_a_controlled_ramp() -> None:
    stepper = RampControl("map csz-ezt-430i", False, "the map lists ramp_c_per_min under "
                          "absent_roles", 5.0)
    ramps = RampControl("map eurotherm-3216", True, "does not say")
    assert ramp_method_refusal(ramps) is None
    assert ramp_method_refusal(stepper) == (
        "method 'ramp' needs a controlled ramp: map csz-ezt-430i has no static ramp (the map "
        "lists ramp_c_per_min under absent_roles); run it as a soak campaign (method 'soak', "
        "ramp_c_per_min = 0)")
    # A controller that says its 0 means "no ramp" takes 0 as the step.
    says = RampControl("map x", True, "", zero_is_step=True)
    assert ramp_refusal(says, 0.0) is None and ramp_refusal(ramps, 0.0) is not None


def test_the_air_is_expected_at_the_commanded_ramp_or_the_chambers_own_rate() -> None:
    from drivers.ramp_rule import moving_rate_c_per_min

    assert moving_rate_c_per_min(RampControl("a", True, ""), 2.0) == 2.0
    assert moving_rate_c_per_min(RampControl("a", True, "", 4.0, zero_is_step=True), 0.0) == 4.0
    assert moving_rate_c_per_min(RampControl("b", False, "", 4.0), 0.0) == 4.0
    assert moving_rate_c_per_min(RampControl("b", False, "", 4.0), 6.0) == 4.0
    assert moving_rate_c_per_min(RampControl("b", False, ""), 0.0) is None
