"""Modbus RTU over a serial line, through the same register maps as TCP.

Two pseudo-terminals joined by a byte relay stand in for a null-modem cable:
pymodbus' RTU server (serving the simulated chamber's register image) opens
one end, the chamber driver opens the other by an ``rtu://`` URL.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
import tty
from collections.abc import AsyncIterator

import numpy as np
import pytest
from pymodbus.datastore import ModbusServerContext
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer

from drivers.chamber import ModbusChamber
from drivers.clock import RealClock
from drivers.modbus_link import ModbusLink
from drivers.registermaps import CHAMBER_MAPS
from simulators.chamber_sim import ChamberPhysics, ChamberRegisterImage
from simulators.faults import SimFaults
from simulators.modbus_server import _PhysicsContext

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs POSIX pseudo-terminals")


def _raw_pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


@pytest.fixture
async def null_modem() -> AsyncIterator[tuple[str, str]]:
    """Two serial device paths whose bytes cross over, like a null-modem cable."""
    (ma, sa, path_a), (mb, sb, path_b) = _raw_pty(), _raw_pty()
    loop = asyncio.get_running_loop()

    def pump(src: int, dst: int) -> None:
        with contextlib.suppress(OSError):  # the other end closed
            os.write(dst, os.read(src, 4096))

    loop.add_reader(ma, pump, ma, mb)
    loop.add_reader(mb, pump, mb, ma)
    try:
        yield path_a, path_b
    finally:
        loop.remove_reader(ma)
        loop.remove_reader(mb)
        for fd in (ma, sa, mb, sb):
            os.close(fd)


@pytest.mark.parametrize("map_name", sorted(CHAMBER_MAPS))
async def test_chamber_over_rtu(null_modem: tuple[str, str], map_name: str) -> None:
    server_path, client_path = null_modem
    clock = RealClock()
    rng = np.random.default_rng(3)
    physics = ChamberPhysics(clock, rng, air_c=-12.5, setpoint_c=-12.5, ambient_c=23.0,
                             die_tau_s=900.0, faults=SimFaults())
    regmap = CHAMBER_MAPS[map_name]
    context = ModbusServerContext(
        devices=_PhysicsContext(ChamberRegisterImage(physics, regmap), SimFaults(), rng),
        single=True)
    server = ModbusSerialServer(context, framer=FramerType.RTU, port=server_path, baudrate=19200)
    serving = asyncio.create_task(server.serve_forever())
    chamber = ModbusChamber(
        ModbusLink(f"rtu://{client_path}?baudrate=19200&parity=N", clock, device="chamber"),
        regmap)
    try:
        for _ in range(50):  # the server opens its port asynchronously
            if server.transport is not None:
                break
            await asyncio.sleep(0.02)
        status = await chamber.read_status()
        # Negative temperatures survive both encodings (scaled s16 / float32 low word first).
        assert status.process_c == pytest.approx(-12.5, abs=0.11)
        await chamber.set_setpoint(-40.0)
        assert (await chamber.read_status()).setpoint_c == pytest.approx(-40.0, abs=0.05)
        assert physics.setpoint_c == pytest.approx(-40.0, abs=0.05)
    finally:
        await chamber.close()
        await server.shutdown()
        serving.cancel()
