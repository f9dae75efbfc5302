"""A thin adapter over the pymodbus 3.11 async client: one request in flight, retries, faults.

Every register access of the chamber and turntable drivers goes through
:class:`ModbusLink`. It owns what pymodbus leaves to the caller:

* one request in flight per client (an ``asyncio.Lock`` around each request),
* reconnect on the next request after the transport dropped, and give up on a request
  as soon as its connection closes (pymodbus would wait out the reply timeout),
* a few quick retries of each *idempotent* request (below),
* translation of every failure into :mod:`drivers.faults`, with the register
  and the Modbus exception's name in the message.

What the link retries, and why there: a fault hits one request, so it is retried
as one request. A status read is several requests where the map's registers are not
adjacent (four on the Eurotherm 3216, five on the Watlow F4T cascade map); at 20 %
faulty requests a five-request read fails 1 − 0.8⁵ = 67 % of the time, and retrying
the whole read (the engine's guard) rarely gets five successes in a row. Retried per
request (``read_attempts = 3``), a request fails 0.2³ = 0.8 %, the status read 3.9 %.

* Reads (FC 1/2/3/4) are always retried: reading has no effect on the device.
* A write is retried only when the driver says it is idempotent: it sets a
  register to a level (a setpoint, a ramp rate, a run/stop level, the table's
  target angles, a one-time setup value), so a repeat after a reply that was lost
  leaves the device as one write would. ``write_attempts`` tries.
* A write that triggers an action (the turntable's move/stop command) is sent
  again only after the device answered SERVER DEVICE BUSY (code 6): it did not act
  and asks for the request again. After a lost reply (timeout, connection closed)
  the device may have acted, and on a positioner whose command is an edge a repeat
  restarts or faults the motion: the fault goes to the engine's guard
  (service/engine/guard.py), which re-sends the whole move (targets, then command)
  and reads the position back.

Exception codes 1–3 (illegal function/address/value) are never retried. A fault
that outlasts the link's tries reaches the caller with the number of tries in its
message; the engine's guard then decides (retry the call, suspend, or fail).
Retries are counted in ``stats`` and logged at DEBUG. The back-off is waited on the
injected clock. pymodbus' own retries and auto-reconnect are switched off. The reply
timeout is wall time on purpose: it guards a socket, not physics, and with a
:class:`~drivers.clock.VirtualClock` a clock-based timeout would fire whenever the
loop is briefly idle while a reply is still in flight.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from urllib.parse import parse_qs, urlparse

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.client.base import ModbusBaseClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.pdu import ModbusPDU

from drivers.clock import Clock
from drivers.faults import (
    MODBUS_EXCEPTION_NAMES,
    ConnectionLost,
    DeviceFault,
    DeviceTimeout,
    ModbusExceptionReply,
    ProtocolError,
    ValueOutOfRange,
)
from drivers.registermaps import Field

DEVICE_BUSY = 6  # Modbus exception: "retransmit the message later"; the device did not act

# pymodbus logs every timeout and dumps frames at ERROR; the fault taxonomy below
# is how failures reach the caller, so keep its logger quiet unless asked.
logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RetryPolicy:
    """How hard to try before a fault reaches the caller."""

    timeout_s: float = 1.0  # wall time per attempt
    read_attempts: int = 3  # tries of a read (1 = no retry)
    write_attempts: int = 3  # tries of a write (an action's: after DEVICE BUSY only)
    backoff_s: float = 0.2  # first backoff, clock time; doubles each retry
    backoff_max_s: float = 5.0


def client_from_url(url: str, timeout_s: float,
                    on_lost: Callable[[], None] | None = None) -> ModbusBaseClient:
    """``tcp://host:port`` or ``rtu:///dev/ttyUSB0?baudrate=19200&parity=N`` → pymodbus client.

    ``on_lost`` is called when the transport closes (pymodbus' ``trace_connect(False)``).
    """
    def trace_connect(up: bool) -> None:
        if not up and on_lost is not None:
            on_lost()

    u = urlparse(url)
    if u.scheme in ("tcp", "modbus+tcp", ""):
        if not u.hostname:
            raise ValueError(f"Modbus URL {url!r} has no host (expected tcp://host:port)")
        return AsyncModbusTcpClient(
            u.hostname, port=u.port or 502, timeout=timeout_s, retries=0, reconnect_delay=0,
            trace_connect=trace_connect,
        )
    if u.scheme == "rtu":
        q = {k: v[-1] for k, v in parse_qs(u.query).items()}
        return AsyncModbusSerialClient(
            u.path,
            baudrate=int(q.get("baudrate", 19200)),
            parity=q.get("parity", "N"),
            stopbits=int(q.get("stopbits", 1)),
            bytesize=int(q.get("bytesize", 8)),
            timeout=timeout_s,
            retries=0,
            reconnect_delay=0,
            trace_connect=trace_connect,
        )
    raise ValueError(f"unsupported Modbus URL scheme {u.scheme!r} in {url!r} (tcp:// or rtu://)")


class ModbusLink:
    """Serialised, retrying register access to one Modbus device."""

    def __init__(
        self,
        url: str,
        clock: Clock,
        *,
        device: str = "modbus",
        device_id: int = 1,
        policy: RetryPolicy | None = None,
    ) -> None:
        self.url = url
        self.clock = clock
        self.device = device
        self.device_id = device_id
        self.policy = policy or RetryPolicy()
        self._client: ModbusBaseClient | None = None
        self._lost = asyncio.Event()  # set when the current client's transport closes
        self._lock = asyncio.Lock()
        self._was_connected = False
        self.stats = {"requests": 0, "retries": 0, "reconnects": 0}
        # Called with a label ("chamber write of register 300") right before every write
        # request goes out, each try included; whatever it raises stops the write unsent.
        # The campaign engine's device fence sets it (the rig lease is confirmed per write).
        self.before_write: Callable[[str], None] | None = None

    # --- public -----------------------------------------------------------
    async def read_field(self, f: Field) -> float:
        words = await self.read_registers(f.address, f.n_registers, f.table)
        return f.decode(words)

    async def read_fields(self, fields: list[Field], max_gap_words: int = 0) -> list[float]:
        """Read several fields in as few requests as the device allows.

        Fields whose addresses are at most ``max_gap_words`` apart share one
        request (a device that rejects reads over undefined registers has 0).
        """
        order = sorted(range(len(fields)), key=lambda i: fields[i].address)
        values: list[float] = [0.0] * len(fields)
        block: list[int] = []
        # One request reads one table: sort by table, then address.
        order = sorted(order, key=lambda i: (fields[i].table, fields[i].address))
        for i in [*order, -1]:
            if block and (i < 0 or fields[i].table != fields[block[0]].table
                          or fields[i].address - _end(fields[block[-1]]) > max_gap_words
                          or _end(fields[i]) - fields[block[0]].address > 125):
                start = fields[block[0]].address
                words = await self.read_registers(start, _end(fields[block[-1]]) - start,
                                                  fields[block[0]].table)
                for j in block:
                    off = fields[j].address - start
                    values[j] = fields[j].decode(words[off: off + fields[j].n_registers])
                block = []
            if i >= 0:
                block.append(i)
        return values

    async def write_field(self, f: Field, value: float, *, idempotent: bool = False) -> None:
        """Write ``value`` to ``f``; ``idempotent``: a level a repeat leaves unchanged, so a
        lost reply is retried too (module docstring); else only DEVICE BUSY is."""
        try:
            words = f.encode(value)
        except (ValueError, OverflowError) as exc:
            raise ValueOutOfRange(self.device, f"{value} at register {f.address}: {exc}") from exc
        tries = max(1, self.policy.write_attempts)
        if f.table == "coil":  # FC 5
            await self._request("write", f.address, lambda c: c.write_coil(
                f.address, bool(words[0]), device_id=self.device_id), tries,
                repeatable=idempotent)
        elif f.single_write:  # FC 6: controllers that refuse FC 16
            await self._request("write", f.address, lambda c: c.write_register(
                f.address, words[0], device_id=self.device_id), tries,
                repeatable=idempotent)
        else:
            await self.write_registers(f.address, words, idempotent=idempotent)

    async def read_registers(self, address: int, count: int,
                             table: str = "holding") -> list[int]:
        """``count`` words (or bits, as 0/1, from coils and discrete inputs) at ``address``."""
        read = {"holding": "read_holding_registers", "input": "read_input_registers",
                "coil": "read_coils", "discrete": "read_discrete_inputs"}[table]
        rr = await self._request(
            "read", address, lambda c: getattr(c, read)(
                address, count=count, device_id=self.device_id),
            max(1, self.policy.read_attempts),
        )
        got = [int(b) for b in rr.bits[:count]] if table in ("coil", "discrete") \
            else list(rr.registers)
        if len(got) != count:  # a short reply is a broken device, not noise
            raise ProtocolError(
                self.device, f"asked {count} registers at {address}, got {len(got)}"
            )
        return got

    async def write_registers(self, address: int, words: list[int], *,
                              idempotent: bool = False) -> None:
        """FC 16; ``idempotent`` as for :meth:`write_field`."""
        await self._request(
            "write", address,
            lambda c: c.write_registers(address, words, device_id=self.device_id),
            max(1, self.policy.write_attempts), repeatable=idempotent,
        )

    async def close(self) -> None:
        async with self._lock:
            self._drop()

    # --- internals ----------------------------------------------------------
    async def _request(
        self, what: str, address: int, call: Callable[[ModbusBaseClient], Awaitable[ModbusPDU]],
        tries: int, *, repeatable: bool = True,
    ) -> ModbusPDU:
        """``call`` up to ``tries`` times; ``repeatable=False`` (an action): a lost reply is
        not retried, since the device may have acted; DEVICE BUSY still is."""
        async with self._lock:
            last: DeviceFault | None = None
            made = 0
            for attempt in range(tries):
                if attempt:
                    assert last is not None
                    self.stats["retries"] += 1
                    log.debug("%s: %s; try %d of %d", self.device, last.message,
                              attempt + 1, tries)
                    delay = min(self.policy.backoff_s * 2 ** (attempt - 1),
                                self.policy.backoff_max_s)
                    await self.clock.sleep(delay)
                task = asyncio.current_task()
                cancels = task.cancelling() if task is not None else 0
                made = attempt + 1
                try:
                    client = await self._connected()
                    if what == "write" and self.before_write is not None:
                        self.before_write(f"{self.device} write of register {address}")
                    self.stats["requests"] += 1
                    rr = await self._reply(call(client))
                    if task is not None and task.cancelling() > cancels:
                        # pymodbus awaits the reply with asyncio.wait_for, which (Python
                        # < 3.12) returns a reply that arrived with our cancellation and
                        # drops the cancellation: give it back, or a service shutdown
                        # (or a lost rig lease) is ignored and the campaign goes on.
                        raise asyncio.CancelledError
                except DeviceFault as fault:
                    last = fault
                    continue
                except ConnectionException as exc:
                    self._drop()
                    last = ConnectionLost(self.device, f"{what}: {exc}")
                    if not repeatable:
                        break
                    continue
                except ModbusIOException as exc:
                    # pymodbus turns a cancellation of our task into ModbusIOException;
                    # give the cancellation back instead of retrying it as a timeout.
                    task = asyncio.current_task()
                    if task is not None and task.cancelling():
                        self._drop()
                        raise asyncio.CancelledError from exc
                    if not client.connected:
                        self._drop()
                        last = ConnectionLost(self.device, f"{what}: connection lost ({exc})")
                    else:
                        last = DeviceTimeout(
                            self.device, f"{what}: no reply within {self.policy.timeout_s} s")
                    if not repeatable:
                        break
                    continue
                except ModbusException as exc:
                    raise ProtocolError(self.device, f"{what}: {exc}") from exc
                if rr.isError():
                    code = getattr(rr, "exception_code", None)
                    name = MODBUS_EXCEPTION_NAMES.get(code or 0, "unknown exception")
                    last = ModbusExceptionReply(
                        self.device, f"{what} register {address}: exception code {code} "
                                     f"({name})", code, address)
                    # Illegal function/address/value will not heal by retrying: report at once.
                    # An action is sent again only when the device said it did not act.
                    if not last.retryable or not (repeatable or code == DEVICE_BUSY):
                        break
                    continue
                return rr
            assert last is not None
            raise _after_tries(last, made)

    async def _reply(self, request: Awaitable[ModbusPDU]) -> ModbusPDU:
        """The request's reply; :class:`ConnectionException` as soon as the transport closes.

        pymodbus waits out the whole reply timeout for a request whose connection the
        device closed (1.1 s wall against 1 ms for a reply): a reply that cannot come is
        not waited for, so a dropped connection costs a reconnect, not a timeout.
        """
        reply = asyncio.ensure_future(request)
        closed = asyncio.ensure_future(self._lost.wait())
        try:
            await asyncio.wait({reply, closed}, return_when=asyncio.FIRST_COMPLETED)
        except asyncio.CancelledError:
            reply.cancel()
            closed.cancel()
            raise
        closed.cancel()
        if reply.done():
            return reply.result()
        reply.cancel()  # pymodbus releases its lock; the link drops this client
        reply.add_done_callback(_retrieve)
        raise ConnectionException("the device closed the connection")

    async def _connected(self) -> ModbusBaseClient:
        if self._client is not None and self._client.connected:
            return self._client
        if self._client is not None:
            self._drop()
        if self._was_connected:
            self.stats["reconnects"] += 1
        self._lost = asyncio.Event()
        self._client = client_from_url(self.url, self.policy.timeout_s, on_lost=self._lost.set)
        try:
            # pymodbus bounds the connect by ``timeout`` itself (and then idles 0.1 s wall).
            ok = await self._client.connect()
        except OSError:
            ok = False
        if not ok:
            self._drop()
            raise ConnectionLost(self.device, f"cannot connect to {self.url}")
        self._was_connected = True
        return self._client

    def _drop(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None


def _retrieve(fut: asyncio.Future) -> None:
    """Consume the outcome of a request abandoned on a closed connection (no asyncio warning)."""
    if not fut.cancelled():
        fut.exception()


def _after_tries(fault: DeviceFault, tries: int) -> DeviceFault:
    """``fault`` with how often it was tried in its message (a persistent fault says so)."""
    if tries > 1:
        fault.message = f"{fault.message} ({tries} tries)"
        fault.args = (f"{fault.device}: {fault.message}",)
    return fault


def _end(f: Field) -> int:
    """One past the last register of ``f``."""
    return f.address + f.n_registers
