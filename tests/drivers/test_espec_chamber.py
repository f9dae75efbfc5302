"""The ESPEC P-300/SCP-220 driver against its twin over the real wire (TCP loopback):
status, setpoint, modes, refusals, the park, the rig config keys and ``rig check``."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.espec_chamber import EspecChamber, EspecSettings
from drivers.faults import ConfigurationFault, DeviceTimeout, ValueOutOfRange
from service.engine.rigs import RigConfigError, open_rig, rig_config_errors
from service.rig_check import Check, check_rig, format_report, passed
from simulators.chamber_sim import ChamberPhysics
from simulators.espec_sim import EspecController, EspecSetup, start_espec_server
from simulators.rig import start_sim_rig


@asynccontextmanager
async def _twin(clock: VirtualClock, setup: EspecSetup | None = None,
                **settings: Any) -> AsyncIterator[tuple[EspecChamber, ChamberPhysics]]:
    physics = ChamberPhysics(clock, np.random.default_rng(1), air_c=23.0, setpoint_c=23.0)
    server = await start_espec_server(EspecController(physics, setup))
    chamber = EspecChamber(EspecSettings(url=server.url, range_c=(-40.0, 85.0), **settings),
                           clock, timeout_s=0.5)
    try:
        yield chamber, physics
    finally:
        await chamber.close()
        await server.stop()


async def test_status_setpoint_and_modes_over_the_wire() -> None:
    clock = VirtualClock()
    async with _twin(clock, EspecSetup(mode="STANDBY")) as (chamber, physics):
        st = await chamber.read_status()
        assert not st.running and st.working_setpoint_c is None and st.ramp_c_per_min == 0.0
        assert st.setpoint_c == pytest.approx(23.0)
        await chamber.set_setpoint(30.04)
        await chamber.run()
        assert physics.running and physics.setpoint_c == pytest.approx(30.0)
        await clock.sleep(1200.0)
        st = await chamber.read_status()
        assert st.running and st.setpoint_c == 30.0 and st.process_c == pytest.approx(30.0, abs=0.2)
        await chamber.stop()
        assert not (await chamber.read_status()).running


async def test_a_ramp_slower_than_the_chamber_steps_is_refused_naming_the_fix() -> None:
    clock = VirtualClock()
    async with _twin(clock) as (chamber, _):
        await chamber.set_ramp_rate(0.0)
        with pytest.raises(ValueOutOfRange, match=r"own rate, which is not stated \(chamber\."
                           r"max_rate_c_per_min\); run the campaign with ramp_c_per_min = 0"):
            await chamber.set_ramp_rate(1.0)
    async with _twin(clock, max_rate_c_per_min=3.0) as (chamber, _):
        await chamber.set_ramp_rate(3.0)  # the chamber cannot go faster: stepping is that ramp
        await chamber.set_ramp_rate(5.0)
        with pytest.raises(ValueOutOfRange, match=r"ramp_c_per_min = 0 \(step\) or ≥ 3"):
            await chamber.set_ramp_rate(2.0)


async def test_refusals_name_the_reason_and_are_permanent() -> None:
    clock = VirtualClock()
    async with _twin(clock, EspecSetup(key_protect=True)) as (chamber, _):
        with pytest.raises(ConfigurationFault, match="NA:PROTECT ON.*key protect off"):
            await chamber.set_setpoint(25.0)
    async with _twin(clock, EspecSetup(upper_limit_c=60.0)) as (chamber, _):
        with pytest.raises(ConfigurationFault, match="DATA OUT OF RANGE"):
            await chamber.set_setpoint(70.0)  # inside the rig's range, beyond the controller's
        with pytest.raises(ValueOutOfRange, match="outside -40.0…85.0"):
            await chamber.set_setpoint(90.0)


async def test_a_running_program_is_not_taken_over() -> None:
    clock = VirtualClock()
    async with _twin(clock, EspecSetup(mode="RUN")) as (chamber, physics):
        with pytest.raises(ConfigurationFault, match="a program is running"):
            await chamber.run()
        assert (await chamber.read_mode()) == "RUN"


async def test_from_off_the_controller_is_powered_on_into_constant_mode() -> None:
    clock = VirtualClock()
    async with _twin(clock, EspecSetup(mode="OFF")) as (chamber, physics):
        await chamber.run()
        assert (await chamber.read_mode()) == "CONSTANT" and physics.running


async def test_alarms_are_reported_by_code() -> None:
    clock = VirtualClock()
    async with _twin(clock, EspecSetup(alarms=(12, 31))) as (chamber, _):
        assert (await chamber.read_status()).alarms == ("alarm 12", "alarm 31")


async def test_the_rs485_address_prefixes_commands_and_a_wrong_one_times_out() -> None:
    clock = VirtualClock()
    async with _twin(clock, EspecSetup(address=3), address=3) as (chamber, _):
        assert (await chamber.read_temp()).process_c == pytest.approx(23.0, abs=0.2)
    async with _twin(clock, EspecSetup(address=3), address=4) as (chamber, _):
        with pytest.raises(DeviceTimeout, match="no reply to 'TEMP\\?'"):
            await chamber.read_temp()


async def test_park_clamps_to_the_range_and_stops_when_the_rig_says() -> None:
    clock = VirtualClock()
    async with _twin(clock, safe_setpoint_c=20.0, safe_stop=True) as (chamber, physics):
        assert await chamber.park() == "setpoint 20 °C, controller in standby"
        assert physics.setpoint_c == 20.0 and not physics.running
        assert await chamber.park(100.0) == ("setpoint 85 °C (the range's edge; 100 °C asked), "
                                             "controller in standby")


def _espec_rig(url: str, sim: Any, **chamber: Any) -> dict[str, Any]:
    return {"name": "espec-bench",
            "chamber": {"driver": "espec", "url": url, "range_c": [-40, 85], **chamber},
            "turntable": {"url": sim.table_url, "map": sim.table_map},
            "sensors": [{"url": sim.sensor_url}]}


def test_rig_config_keys_are_validated_strictly() -> None:
    sensors = [{"url": "/dev/ttyUSB0"}]
    table = {"url": "tcp://10.0.0.6:502"}
    ok = {"driver": "espec", "url": "/dev/ttyUSB1", "range_c": [-40, 85]}
    assert rig_config_errors(ok, table, sensors) == []
    got = dict(rig_config_errors({**ok, "map": "eurotherm-3216", "rnage_c": 1}, table, sensors))
    assert "unknown key" in got["chamber.map"]
    assert "did you mean 'range_c'" in got["chamber.rnage_c"]
    got = dict(rig_config_errors({"driver": "espec", "url": "rtu:///dev/ttyUSB1",
                                  "address": 40, "safe_setpoint_c": 100, "safe_stop": "yes"},
                                 table, sensors))
    assert "required for an ESPEC chamber" in got["chamber.range_c"]
    assert "serial port" in got["chamber.url"]
    assert "RS-485 address 1…16" in got["chamber.address"]
    assert "expected true or false" in got["chamber.safe_stop"]
    got = dict(rig_config_errors({**ok, "safe_setpoint_c": 100}, table, sensors))
    assert "outside range_c [-40, 85]" in got["chamber.safe_setpoint_c"]


async def test_open_rig_refuses_an_espec_rig_without_a_range() -> None:
    rig = {"name": "r", "chamber": {"driver": "espec", "url": "/dev/null"},
           "turntable": {"url": "tcp://127.0.0.1:1"}, "sensors": [{"url": "/dev/null"}]}
    with pytest.raises(RigConfigError, match="chamber.range_c: required"):
        async with open_rig(rig, VirtualClock()):
            pass


def _by(checks: list[Check], name: str) -> Check:
    return next(c for c in checks if c.device == "chamber" and c.check == name)


@asynccontextmanager
async def _espec_sim_rig(clock: VirtualClock, setup: EspecSetup
                         ) -> AsyncIterator[tuple[Any, str]]:
    """The twin rig's table and sensor, its chamber physics behind the ESPEC protocol."""
    async with start_sim_rig(clock, seed=4) as sim:
        server = await start_espec_server(EspecController(sim.chamber, setup))
        try:
            yield sim, server.url
        finally:
            await server.stop()


async def test_rig_check_passes_over_the_espec_protocol_and_puts_the_nudge_back() -> None:
    clock = VirtualClock()
    async with _espec_sim_rig(clock, EspecSetup()) as (sim, url):
        checks = await check_rig(_espec_rig(url, sim), move=True, clock=clock)
        assert sim.chamber.setpoint_c == pytest.approx(23.0)
    report = format_report("espec-bench", checks)
    assert passed(checks), report
    assert "controller P300, maximum 180 °C" in _by(checks, "identity").detail
    assert _by(checks, "pv_vs_die").status == "pass"
    assert _by(checks, "setpoint_nudge").detail == "SP 23.0 → 23.5 → 23.0 °C"
    assert "no ramp to command" in _by(checks, "ramp").detail
    assert _by(checks, "pv_follows").status == "pass"


async def test_rig_check_fails_a_running_program_and_a_range_beyond_the_limits() -> None:
    clock = VirtualClock()
    async with _espec_sim_rig(clock, EspecSetup(mode="RUN", upper_limit_c=60.0)) as (sim, url):
        checks = await check_rig(_espec_rig(url, sim), move=True, clock=clock)
    assert not passed(checks)
    limits = _by(checks, "limits")
    assert limits.status == "fail" and "narrow chamber.range_c to [-40, 60]" in limits.fix
    assert _by(checks, "mode").status == "fail"
    assert "end the program" in _by(checks, "mode").fix


async def test_rig_check_names_the_espec_settings_when_nothing_answers() -> None:
    clock = VirtualClock()
    async with _espec_sim_rig(clock, EspecSetup()) as (sim, _):
        checks = await check_rig(_espec_rig("tcp://127.0.0.1:1", sim), clock=clock)
    connect = _by(checks, "connect")
    assert connect.status == "fail" and "RS-485 address (chamber.address)" in connect.fix
