"""Serve a register image (chamber or table physics) over Modbus TCP with pymodbus 3.11.

The image is consulted on every request (``read``/``write`` advance the
physics to ``clock.now()`` first), and :class:`SimFaults` is applied per request.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.datastore.context import ModbusBaseDeviceContext
from pymodbus.server import ModbusTcpServer
from pymodbus.transport import NULLMODEM_HOST

from simulators.faults import SimFaults

#: ``host`` for an in-memory server: pymodbus' null modem, no sockets (tests, benchmarks).
IN_MEMORY_HOST = NULLMODEM_HOST


class RegisterImage(Protocol):
    def read(self, address: int, count: int) -> list[int] | ExcCodes: ...

    def write(self, address: int, values: list[int]) -> None | ExcCodes: ...


#: pymodbus' datastore letters → the map's table names (drivers.registermaps.TABLES).
_TABLES = {"h": "holding", "i": "input", "c": "coil", "d": "discrete"}


def read_block(image: dict[int, int], address: int, count: int) -> list[int] | ExcCodes:
    """Words ``address…address+count-1`` of a sparse image.

    Undefined registers *between* defined ones read as 0, as on controllers whose
    parameter tables are dense; anything outside the defined span is an illegal address.
    """
    lo, hi = min(image), max(image)
    if count < 1 or address < lo or address + count - 1 > hi:
        return ExcCodes.ILLEGAL_ADDRESS
    return [image.get(a, 0) for a in range(address, address + count)]


class _PhysicsContext(ModbusBaseDeviceContext):
    """Holding registers (FC 3/6/16) backed by a :class:`RegisterImage`; faults injected here."""

    def __init__(self, image: RegisterImage, faults: SimFaults, rng: np.random.Generator) -> None:
        self.image = image
        self.faults = faults
        self.rng = rng

    def reset(self) -> None:  # required by the pymodbus interface; the physics has no reset
        pass

    def _busy(self) -> bool:
        return self.faults.p_exception > 0 and self.rng.random() < self.faults.p_exception

    def getValues(  # noqa: N802 - pymodbus name
        self, func_code: int, address: int, count: int = 1
    ) -> list[int] | list[bool] | ExcCodes:
        table = _TABLES.get(self.decode(func_code))
        # An image with tables (a chamber map may use input registers, coils, discrete
        # inputs) serves each; one without serves holding registers only.
        read_table = getattr(self.image, "read_table", None)
        if table is None or (read_table is None and table != "holding"):
            return ExcCodes.ILLEGAL_FUNCTION
        if self._busy():
            return ExcCodes.DEVICE_BUSY
        if read_table is None:
            return self.image.read(address, count)
        got = read_table(table, address, count)
        if isinstance(got, list) and table in ("coil", "discrete"):
            return [bool(b) for b in got]
        return got

    def setValues(  # noqa: N802 - pymodbus name
        self, func_code: int, address: int, values: list[int] | list[bool]
    ) -> None | ExcCodes:
        table = _TABLES.get(self.decode(func_code))
        write_table = getattr(self.image, "write_table", None)
        if table not in ("holding", "coil") or (write_table is None and table != "holding"):
            return ExcCodes.ILLEGAL_FUNCTION
        if self._busy():
            return ExcCodes.DEVICE_BUSY
        if func_code == 16 and getattr(self.image, "ignores_fc16", False):
            return None  # acknowledged, not executed (ControllerSetup.single_writes_only)
        if write_table is None:
            return self.image.write(address, [int(v) for v in values])
        return write_table(table, address, [int(v) for v in values])


@dataclass
class ModbusSimServer:
    """A running simulated Modbus TCP device."""

    server: ModbusTcpServer
    host: str
    port: int

    @property
    def url(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    async def stop(self) -> None:
        await self.server.shutdown()


async def start_modbus_server(
    image: RegisterImage | dict[int, RegisterImage],
    faults: SimFaults,
    rng: np.random.Generator,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
) -> ModbusSimServer:
    """Listen on ``host:port`` (0 = ephemeral) and serve ``image`` to any device id, or
    each image of a ``{unit id: image}`` to its unit id only (drives sharing one bus: a
    request to another unit id goes unanswered, as on RS-485).

    With ``host=IN_MEMORY_HOST`` the server is pymodbus' in-process null modem
    (``port`` must then be a non-zero number unique in the process); drivers reach
    it with ``tcp://__pymodbus_nullmodem:PORT``.
    """
    if host == IN_MEMORY_HOST and not port:
        raise ValueError("an in-memory Modbus server needs an explicit non-zero port")
    if isinstance(image, dict):
        context = ModbusServerContext(
            devices={uid: _PhysicsContext(img, faults, rng) for uid, img in image.items()},
            single=False)
    else:
        context = ModbusServerContext(devices=_PhysicsContext(image, faults, rng), single=True)
    holder: dict[str, ModbusTcpServer] = {}

    def trace_packet(sending: bool, data: bytes) -> bytes:
        # Replies can be swallowed (client times out) or replaced by a closed socket.
        if not sending:
            return data
        if faults.p_drop > 0 and rng.random() < faults.p_drop:
            asyncio.get_running_loop().call_soon(_drop_all, holder["server"])
            return b""
        if faults.p_no_reply > 0 and rng.random() < faults.p_no_reply:
            return b""
        return data

    server = ModbusTcpServer(context, address=(host, port), trace_packet=trace_packet)
    holder["server"] = server
    await server.serve_forever(background=True)
    sockets = getattr(server.transport, "sockets", None)
    bound_port = sockets[0].getsockname()[1] if sockets else port
    return ModbusSimServer(server, host, bound_port)


def _drop_all(server: ModbusTcpServer) -> None:
    for conn in list(server.active_connections.values()):
        conn.close()
