"""Chamber and turntable drivers against the simulators over loopback Modbus TCP."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from dataclasses import dataclass

import numpy as np
import pytest

from drivers.chamber import ModbusChamber
from drivers.clock import VirtualClock
from drivers.faults import ConnectionLost, DeviceTimeout, ExceptionReply, ValueOutOfRange
from drivers.modbus_link import ModbusLink, RetryPolicy
from drivers.registermaps import CHAMBER_MAPS, SOAKCAL_TABLE
from drivers.turntable import ModbusTurntable
from simulators.chamber_sim import ChamberPhysics, ChamberRegisterImage
from simulators.faults import SimFaults
from simulators.modbus_server import ModbusSimServer, start_modbus_server
from simulators.turntable_sim import TurntablePhysics, TurntableRegisterImage
from tests.drivers.refusing_port import refusing_port

#: The rigs' links: a wall timeout long enough that a reply from a loaded test machine (four
#: workers on two cores) is not taken for a lost one; backoff is clock time (virtual).
STEADY = RetryPolicy(timeout_s=2.0, read_attempts=3, write_attempts=3, backoff_s=0.5)
#: A short wall timeout for the tests whose replies never come, to keep them fast.
FAST = RetryPolicy(timeout_s=0.15, read_attempts=3, write_attempts=3, backoff_s=0.5)


@dataclass
class ChamberRig:
    clock: VirtualClock
    physics: ChamberPhysics
    faults: SimFaults
    server: ModbusSimServer
    driver: ModbusChamber


@dataclass
class TableRig:
    clock: VirtualClock
    physics: TurntablePhysics
    faults: SimFaults
    server: ModbusSimServer
    driver: ModbusTurntable


@pytest.fixture(params=sorted(CHAMBER_MAPS))
async def chamber_rig(request: pytest.FixtureRequest) -> AsyncIterator[ChamberRig]:
    clock = VirtualClock()
    faults = SimFaults()
    rng = np.random.default_rng(7)
    physics = ChamberPhysics(clock, rng, faults=faults)
    regmap = CHAMBER_MAPS[request.param]
    server = await start_modbus_server(ChamberRegisterImage(physics, regmap), faults, rng)
    driver = ModbusChamber(ModbusLink(server.url, clock, device="chamber", policy=STEADY), regmap)
    yield ChamberRig(clock, physics, faults, server, driver)
    await driver.link.close()
    await server.stop()


@pytest.fixture
async def table_rig() -> AsyncIterator[TableRig]:
    clock = VirtualClock()
    faults = SimFaults()
    physics = TurntablePhysics(clock, faults=faults, slew_deg_per_s=10.0, accel_deg_per_s2=20.0,
                               settle_s=3.0)
    server = await start_modbus_server(TurntableRegisterImage(physics, SOAKCAL_TABLE), faults,
                                       np.random.default_rng(8))
    driver = ModbusTurntable(ModbusLink(server.url, clock, device="turntable", policy=STEADY),
                             SOAKCAL_TABLE)
    yield TableRig(clock, physics, faults, server, driver)
    await driver.link.close()
    await server.stop()



async def test_chamber_status_roundtrip(chamber_rig: ChamberRig) -> None:
    ch = chamber_rig.driver
    # A map without a static ramp (absent_roles) steps: only 0 can be set, and reads 0.
    rate = 2.0 if ch.regmap.ramp_c_per_min is not None else 0.0
    await ch.set_ramp_rate(rate)
    await ch.set_setpoint(-40.0)
    st = await ch.read_status()
    assert st.setpoint_c == -40.0
    assert st.ramp_c_per_min == rate
    assert (st.working_setpoint_c is None) is (ch.regmap.working_setpoint_c is None)
    # A controller without a run register controls whenever powered (eurotherm-3216).
    assert st.running is (chamber_rig.driver.regmap.run is None)
    assert st.process_c == pytest.approx(23.0, abs=0.2)


async def test_a_ramp_rate_the_register_cannot_hold_is_refused(chamber_rig: ChamberRig) -> None:
    """Whole-°C/min registers (watlow-f4t-cascade) would run 1.5 as 2 and 0.4 as 0."""
    ch = chamber_rig.driver
    f = ch.regmap.ramp_c_per_min
    if f is None:  # no ramp register: any rate but 0 is refused (test_map_roles_sequences)
        return
    for rate in (1.5, 0.4):
        held = f.decode(f.encode(rate))
        if abs(held - rate) <= 0.05 * rate:
            await ch.set_ramp_rate(rate)  # the register holds it: written as asked
            assert (await ch.read_status()).ramp_c_per_min == pytest.approx(rate, rel=0.05)
            continue
        with pytest.raises(ValueOutOfRange, match=f"register {f.address}: it would hold"):
            await ch.set_ramp_rate(rate)


async def test_chamber_ramps_then_settles(chamber_rig: ChamberRig) -> None:
    ch, clock = chamber_rig.driver, chamber_rig.clock
    if ch.regmap.working_setpoint_c is None or ch.regmap.ramp_c_per_min is None:
        await ch.set_setpoint(-17.0)  # steps: the air goes at the chamber's 5 °C/min
        await ch.run()
        await clock.sleep(900.0)  # 40 °C at 5 °C/min is 8 min, then the air's lag
        st = await ch.read_status()
        assert st.working_setpoint_c is None and st.setpoint_c == -17.0
        assert st.process_c == pytest.approx(-17.0, abs=0.15)
        assert chamber_rig.physics.die_c > chamber_rig.physics.air_c
        return
    await ch.set_ramp_rate(2.0)
    await ch.set_setpoint(-17.0)
    await ch.run()
    await clock.sleep(600.0)  # 10 min at 2 °C/min: WSP 23 → 3 °C
    st = await ch.read_status()
    assert st.running
    assert st.working_setpoint_c == pytest.approx(3.0, abs=0.1)
    assert st.process_c > st.working_setpoint_c  # the air lags the ramp when cooling
    await clock.sleep(1800.0)
    st = await ch.read_status()
    assert st.working_setpoint_c == pytest.approx(-17.0, abs=0.05)
    assert st.process_c == pytest.approx(-17.0, abs=0.15)
    assert st.alarms == ()
    # The die lags the air: still warmer than the air after the ramp.
    assert chamber_rig.physics.die_c > chamber_rig.physics.air_c


async def test_chamber_rejects_out_of_range_setpoint_locally(chamber_rig: ChamberRig) -> None:
    with pytest.raises(ValueOutOfRange):
        await chamber_rig.driver.set_setpoint(500.0)
    assert chamber_rig.driver.link.stats["requests"] == 0


async def test_device_rejects_value_with_exception_reply(chamber_rig: ChamberRig) -> None:
    link = chamber_rig.driver.link
    with pytest.raises(ExceptionReply) as err:
        await link.write_field(chamber_rig.driver.regmap.setpoint_c, -100.0)  # below −70 °C
    assert err.value.code == 3
    assert link.stats["retries"] == 0  # illegal value is not retried


async def test_illegal_address_is_exception_reply(chamber_rig: ChamberRig) -> None:
    with pytest.raises(ExceptionReply) as err:
        await chamber_rig.driver.link.read_registers(40000, 2)  # past every map
    assert err.value.code == 2


async def test_deviation_alarm(chamber_rig: ChamberRig) -> None:
    ch = chamber_rig.driver
    if "deviation_low" not in ch.regmap.alarm_bits.values():
        pytest.skip("this map has no deviation alarm bit (its alarm types are configured)")
    # Step change (the twin's ramp register 0): WSP jumps, the air cannot follow. Written
    # to the register: the driver refuses 0 on a map that does not say 0 means "no ramp".
    await ch.link.write_field(ch.regmap.ramp_c_per_min, 0.0)
    await ch.set_setpoint(60.0)
    await ch.run()
    await chamber_rig.clock.sleep(10.0)
    assert "deviation_low" in (await ch.read_status()).alarms


async def test_stuck_process_value(chamber_rig: ChamberRig) -> None:
    ch = chamber_rig.driver
    await ch.set_setpoint(0.0)
    await ch.run()
    chamber_rig.faults.stuck_process_value = True
    pv0 = (await ch.read_status()).process_c
    await chamber_rig.clock.sleep(1200.0)
    assert (await ch.read_status()).process_c == pv0
    assert chamber_rig.physics.air_c < pv0 - 5.0  # the air moved, the reading did not


async def test_exception_replies_are_retried(chamber_rig: ChamberRig) -> None:
    chamber_rig.faults.p_exception = 0.3
    for _ in range(10):  # one request each (a status read is several on gap-0 maps)
        await chamber_rig.driver.read_process_c()
    assert chamber_rig.driver.link.stats["retries"] > 0


async def test_persistent_busy_reports_exception_reply(chamber_rig: ChamberRig) -> None:
    chamber_rig.faults.p_exception = 1.0
    with pytest.raises(ExceptionReply) as err:
        await chamber_rig.driver.read_status()
    assert err.value.code == 6
    assert chamber_rig.driver.link.stats["requests"] == STEADY.read_attempts


async def test_no_reply_times_out_then_recovers(chamber_rig: ChamberRig) -> None:
    rig = chamber_rig
    ch = ModbusChamber(ModbusLink(rig.server.url, rig.clock, device="chamber", policy=FAST),
                       rig.driver.regmap)
    chamber_rig.faults.p_no_reply = 1.0
    with pytest.raises(DeviceTimeout):
        await ch.read_status()
    chamber_rig.faults.p_no_reply = 0.0
    st = await ch.read_status()
    await ch.link.close()
    assert st.process_c == pytest.approx(23.0, abs=0.2)


async def test_dropped_connection_reported_then_reconnects(chamber_rig: ChamberRig) -> None:
    ch = chamber_rig.driver
    await ch.read_status()
    chamber_rig.faults.p_drop = 1.0
    with pytest.raises(ConnectionLost):
        await ch.read_status()
    chamber_rig.faults.p_drop = 0.0
    await ch.read_status()
    assert ch.link.stats["reconnects"] >= 1


async def test_intermittent_drops_are_absorbed(chamber_rig: ChamberRig) -> None:
    chamber_rig.faults.p_drop = 0.2
    for _ in range(5):
        await chamber_rig.driver.set_setpoint(10.0)
    chamber_rig.faults.p_drop = 0.0
    assert (await chamber_rig.driver.read_status()).setpoint_c == 10.0


async def test_nobody_listening_is_connection_lost(chamber_rig: ChamberRig) -> None:
    await chamber_rig.server.stop()
    with refusing_port(chamber_rig.server.port) as port:
        link = ModbusLink(f"tcp://127.0.0.1:{port}", chamber_rig.clock, device="gone",
                          policy=FAST)
        with pytest.raises(ConnectionLost):
            await link.read_registers(1, 1)


async def test_table_moves_and_reports_in_position(table_rig: TableRig) -> None:
    tt, clock = table_rig.driver, table_rig.clock
    await tt.move_to((90.0, -45.0, 10.0))
    st = await tt.read_status()
    assert st.moving and not st.in_position
    await clock.sleep(5.0)  # 10 °/s with 20 °/s² ramps: 90° takes 9.5 s
    mid = await tt.read_status()
    assert 0.0 < mid.angles_deg[0] < 90.0
    await clock.sleep(5.0)
    arrived = await tt.read_status()
    assert arrived.angles_deg == pytest.approx((90.0, -45.0, 10.0))
    assert not arrived.moving and not arrived.in_position  # settling
    await clock.sleep(3.0)
    assert (await tt.read_status()).in_position


async def test_table_never_in_position(table_rig: TableRig) -> None:
    table_rig.faults.never_in_position = True
    await table_rig.driver.move_to((10.0, 0.0, 0.0))
    await table_rig.clock.sleep(60.0)
    st = await table_rig.driver.read_status()
    assert st.angles_deg[0] == pytest.approx(10.0) and not st.in_position


async def test_table_encoder_error_and_stop(table_rig: TableRig) -> None:
    table_rig.physics.encoder_error_deg = (0.5, 0.0, 0.0)
    await table_rig.driver.move_to((20.0, 0.0, 0.0))
    await table_rig.clock.sleep(1.0)
    await table_rig.driver.stop()
    here = table_rig.physics.true_angles_deg()[0]
    await table_rig.clock.sleep(30.0)
    st = await table_rig.driver.read_status()
    assert st.angles_deg[0] == pytest.approx(here + 0.5, abs=1e-4)
    assert here < 20.0


async def test_table_rejects_wrong_axis_count(table_rig: TableRig) -> None:
    with pytest.raises(ValueOutOfRange):
        await table_rig.driver.move_to((1.0, 2.0))


async def test_in_memory_transport_same_behaviour() -> None:
    """pymodbus' null modem: the fast path, same drivers and images, no sockets."""
    from simulators.modbus_server import IN_MEMORY_HOST

    clock = VirtualClock()
    for i, (name, regmap) in enumerate(sorted(CHAMBER_MAPS.items())):
        faults = SimFaults()
        rng = np.random.default_rng(i)
        physics = ChamberPhysics(clock, rng, faults=faults)
        server = await start_modbus_server(ChamberRegisterImage(physics, regmap), faults, rng,
                                           host=IN_MEMORY_HOST, port=46100 + i)
        assert server.url.startswith("tcp://__pymodbus_nullmodem:"), name
        ch = ModbusChamber(ModbusLink(server.url, clock, policy=FAST), regmap)
        await ch.set_setpoint(-55.5)
        await ch.run()
        await clock.sleep(3 * 3600.0)
        st = await ch.read_status()
        assert st.setpoint_c == -55.5 and st.process_c == pytest.approx(-55.5, abs=0.15)
        faults.p_exception = 1.0
        with pytest.raises(ExceptionReply):
            await ch.read_status()
        await ch.link.close()
        await server.stop()


async def test_concurrent_callers_share_one_link(chamber_rig: ChamberRig) -> None:
    ch = chamber_rig.driver
    results = await asyncio.gather(*(ch.read_status() for _ in range(20)),
                                   ch.set_setpoint(5.0))
    assert all(r.process_c == pytest.approx(23.0, abs=0.2) for r in results[:-1])
    assert (await ch.read_status()).setpoint_c == 5.0


async def test_cancellation_is_not_retried(chamber_rig: ChamberRig) -> None:
    chamber_rig.faults.p_no_reply = 1.0
    policy = RetryPolicy(timeout_s=2.0, read_attempts=3)
    link = ModbusLink(chamber_rig.server.url, chamber_rig.clock, policy=policy)
    task = asyncio.create_task(link.read_registers(1, 1))
    await asyncio.sleep(0.3)  # let the request go out (wall time: the reply never comes)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert link.stats["retries"] == 0
    await link.close()


async def test_client_factory_urls() -> None:
    from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient

    from drivers.modbus_link import client_from_url

    assert isinstance(client_from_url("tcp://10.0.0.5:5020", 1.0), AsyncModbusTcpClient)
    rtu = client_from_url("rtu:///dev/ttyUSB0?baudrate=9600&parity=E", 1.0)
    assert isinstance(rtu, AsyncModbusSerialClient)
    assert rtu.comm_params.baudrate == 9600 and rtu.comm_params.parity == "E"
    with pytest.raises(ValueError):
        client_from_url("udp://host:502", 1.0)
