"""Accelerometer driver over the serial sensor bridge (docs/sensor-bridge.md).

Works with anything ``serial.serial_for_url`` opens: a real port
(``/dev/ttyUSB0``), a pseudo-terminal, or ``socket://host:port`` (the simulated
bridge). pyserial is blocking, so each command runs in a worker thread; one
command is in flight at a time (``asyncio.Lock``). Acquisition duration is
measured on the injected clock. A :class:`MultiplexedBridge` gathers the ``acquire``
calls its channels make in one event-loop turn into one group capture.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Literal, TypeVar

import numpy as np
import serial

from drivers import adxl355
from drivers.bridge_protocol import (
    CHANNEL_MARK,
    FRAMINGS,
    Framing,
    channel_field,
    decode_frame,
    encode_frame,
    split_channel,
)
from drivers.clock import Clock, awaiting_device, run_blocking
from drivers.faults import (
    ConfigurationFault,
    ConnectionLost,
    DeviceFault,
    DeviceTimeout,
    ExceptionReply,
    ProtocolError,
    ValueOutOfRange,
)
from drivers.protocols import Acquisition, SensorIdentity

AcquireMode = Literal["average", "raw"]
log = logging.getLogger(__name__)

#: ``ERR`` codes (docs/sensor-bridge.md): 1, 3, 4 and 7 are permanent refusals, 2 means the
#: bridge received our command garbled (a line fault: retried), anything else (5 sensor
#: not ready, 6 busy) is an ordinary retryable exception reply.
ERR_UNKNOWN_COMMAND = 1
ERR_BAD_FRAME = 2
ERR_BAD_ARGUMENT = 3
ERR_NO_EEPROM = 4
ERR_NO_CHANNEL = 7  # a multiplexing bridge has no sensor on the addressed channel
_PERMANENT_ERRS = (ERR_UNKNOWN_COMMAND, ERR_BAD_ARGUMENT, ERR_NO_EEPROM, ERR_NO_CHANNEL)


# Each port gets its own I/O threads. The event loop's default executor has only
# min(32, cpus + 4) workers: on a 2-core host the seventh sensor's capture of a position
# waited for another's to end, so eight sensors "read at once" took two capture times.
PORT_THREADS = 2  # the command's, and one for a cancelled read running out its timeout
T = TypeVar("T")


class PortThreads:
    """The blocking serial calls of one port, on that port's own threads
    (:func:`drivers.clock.run_blocking`: a virtual clock knows when they are busy)."""

    def __init__(self, name: str, clock: Clock) -> None:
        self._name = name
        self._clock = clock
        self._pool: ThreadPoolExecutor | None = None

    async def run(self, fn: Callable[..., T], *args: object) -> T:
        if self._pool is None:
            self._pool = ThreadPoolExecutor(PORT_THREADS, thread_name_prefix=self._name)
        return await run_blocking(self._clock, self._pool, fn, *args)

    def shutdown(self) -> None:
        """Free the threads once idle (a read still running ends at its own timeout)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None


class SerialLine:
    """One driver's serial port: the open/retry/close discipline both sensor drivers share.

    The port opens on first use, on the port's own threads (:class:`PortThreads`); one
    blocking call runs at a time. A fault that may heal (connection lost, a timeout, a
    garbled line) leaves the stream position unknown: the port is closed and the call
    tried again on a fresh one, up to ``attempts`` times (1 by default: the engine's guard
    is the one retry owner). A cancelled call keeps its worker thread reading until its
    timeout: that thread is handed the port to close, and the next call opens a fresh one.
    """

    def __init__(self, url: str, clock: Clock, *, baudrate: int, timeout_s: float,
                 attempts: int, device: str, name: str) -> None:
        self.url, self.clock, self.device = url, clock, device
        self.baudrate, self.timeout_s, self.attempts = baudrate, timeout_s, attempts
        self._port: serial.SerialBase | None = None
        self._lock = asyncio.Lock()
        self._threads = PortThreads(name, clock)

    async def call(self, fn: Callable[..., T], *args: object) -> T:
        """``fn(port, *args)`` on the port's thread, with the retries above."""
        async with self._lock:
            last: DeviceFault | None = None
            for attempt in range(self.attempts):
                if attempt:
                    await self.clock.sleep(0.1 * attempt)
                try:
                    # a group capture that lost its stream position closed the port itself
                    port = self._port if self._port is not None and self._port.is_open \
                        else await self._threads.run(self._open)
                    io = asyncio.ensure_future(self._threads.run(fn, port, *args))
                    try:
                        return await asyncio.shield(io)
                    except asyncio.CancelledError:
                        self._port = None
                        io.add_done_callback(lambda _f, p=port: p.close())
                        raise
                except (ConnectionLost, DeviceTimeout, ProtocolError) as fault:
                    self._close()
                    last = fault
            assert last is not None
            raise last

    async def close(self) -> None:
        async with self._lock:
            await self._threads.run(self._close)
            self._threads.shutdown()

    def _open(self) -> serial.SerialBase:
        if self._port is None or not self._port.is_open:
            self._port = open_serial_port(self.url, self.baudrate, self.timeout_s, self.device)
        return self._port

    def _close(self) -> None:
        if self._port is not None:
            try:
                self._port.close()
            finally:
                self._port = None


class SerialAccelerometer:
    """:class:`drivers.protocols.Accelerometer` for an ADXL355 behind the bridge.

    ``channel=None`` speaks the unaddressed commands of a one-sensor bridge (the bytes every
    bridge has always understood). A sensor behind a multiplexing bridge is a handle from
    :meth:`MultiplexedBridge.channel`: every command it sends carries ``@<channel>``, every
    reply line must carry the same address, and it shares the bridge's one
    :class:`SerialLine` with the other channels (one command in flight per port).
    """

    def __init__(
        self,
        url: str,
        clock: Clock,
        *,
        mode: AcquireMode = "average",
        baudrate: int = 115200,
        timeout_s: float = 2.0,
        attempts: int = 1,  # 1: no retry here; the engine's guard is the one retry owner
        device: str = "sensor",
        framing: Framing = "v2",
        channel: int | None = None,
        line: SerialLine | None = None,
        on_close: Callable[[], Awaitable[None]] | None = None,
        group: Callable[[SerialAccelerometer, int], Awaitable[list[str]]] | None = None,
    ) -> None:
        if framing not in FRAMINGS:
            raise ValueError(f"sensor framing must be one of {', '.join(FRAMINGS)}, "
                             f"got {framing!r}")
        self.channel = channel
        self._address = [] if channel is None else [channel_field(channel)]
        self.url = url
        self.framing: Framing = framing
        self.clock = clock
        self.mode = mode
        self.baudrate = baudrate
        self.timeout_s = timeout_s  # wall time per reply line
        self.attempts = attempts
        self.device = device
        self.range_g = 2.0
        self.odr_hz = 62.5
        # A channel handle borrows its bridge's line; ``on_close`` hands it back.
        self._line = line or SerialLine(url, clock, baudrate=baudrate, timeout_s=timeout_s,
                                        attempts=attempts, device=device, name=f"bridge {url}")
        self._on_close = on_close
        # A channel's averaged captures go through its bridge, which may group them with
        # its other channels' (MultiplexedBridge.avg_fields); None: this handle's own AVG.
        self._group = group

    # --- protocol -------------------------------------------------------------
    async def identify(self) -> SensorIdentity:
        """``ID`` → identity; v2 bridges add the board uid and the ADXL355 id registers."""
        f = await self._command(["ID"], expect="ID")
        if len(f) == 4:  # v1 bridge: model, serial, firmware only
            return SensorIdentity(model=f[1], serial=f[2], firmware=f[3],
                                  protocol=self.framing)
        if len(f) != 9:
            raise ProtocolError(self.device, f"ID reply has {len(f)} fields, expected 9 "
                                             f"(or 4 from a v1 bridge)")
        try:
            devid_ad, devid_mst, partid, revid = (int(x, 16) for x in f[5:9])
        except ValueError:
            raise ProtocolError(self.device, f"ID reply has a non-hex part id: {f!r}") from None
        return SensorIdentity(model=f[1], serial=f[2], firmware=f[3], board_uid=f[4],
                              devid_ad=devid_ad, devid_mst=devid_mst, partid=partid,
                              revid=revid, protocol=self.framing, channel=self.channel)

    async def bind_serial(self, serial_text: str) -> str:
        """Write the sensor's serial into the fixture EEPROM (``SN``); returns what was stored.

        The one-time binding step when a sensor is fixed to its fixture
        (docs/sensor-bridge.md, "Identity"). ERR 4 (no EEPROM) is a
        ConfigurationFault: bind that fixture in the rig's ``serials`` table.
        """
        text = serial_text.strip()
        if not 1 <= len(text) <= 24 or any(not "!" <= c <= "~" or c in "$*," for c in text):
            raise ValueOutOfRange(self.device, f"serial {serial_text!r} must be 1..24 printable "
                                               f"ASCII characters without blanks, $, * or ,")
        f = await self._command(["SN", text], expect="OK")
        if f[1:] != ["SN", text]:
            raise ProtocolError(self.device, f"EEPROM read back {f[2:]!r} after writing {text!r}")
        return text

    async def configure(self, range_g: float, odr_hz: float) -> None:
        try:
            adxl355.lsb_per_g(range_g)  # validate before touching the wire
        except ValueError as exc:
            raise ValueOutOfRange(self.device, str(exc)) from exc
        if odr_hz <= 0:
            raise ValueOutOfRange(self.device, f"ODR {odr_hz} Hz must be > 0")
        f = await self._command(["CFG", f"{range_g:g}", f"{odr_hz:g}"], expect="OK")
        try:
            self.range_g, self.odr_hz = float(f[2]), float(f[3])
        except (ValueError, IndexError):
            raise ProtocolError(self.device, f"CFG reply malformed: {f!r}") from None

    async def acquire(self, n_samples: int) -> Acquisition:
        if n_samples < 1:
            raise ValueOutOfRange(self.device, f"n_samples must be ≥ 1, got {n_samples}")
        if self.mode == "raw":
            return await self._acquire_raw(n_samples)
        t0 = self.clock.now()
        f = await (self._group(self, n_samples) if self._group is not None
                   else self.avg_fields(n_samples))
        return self._avg_acquisition(f, t0)

    async def avg_fields(self, n_samples: int) -> list[str]:
        """One ``AVG,<n>`` of this sensor alone → the reply's fields (address stripped)."""
        return await self._command(["AVG", n_samples], expect="AVG", n_lines=1,
                                   extra_wait_s=n_samples / self.odr_hz)

    def _avg_acquisition(self, f: list[str], t0: float) -> Acquisition:
        """An ``AVG`` reply's fields (alone or from a group capture) → the Acquisition."""
        if len(f) != 12:
            raise ProtocolError(self.device, f"AVG reply has {len(f)} fields, expected 12")
        try:
            n = int(f[1])
            mean_c = np.array([float(x) for x in f[2:5]])
            sd_c = np.array([float(x) for x in f[5:8]])
            t_mean, t_min, t_max = (float(x) for x in f[8:11])
        except ValueError as exc:
            raise ProtocolError(self.device, f"AVG reply has a non-number: {exc}") from None
        scale = adxl355.lsb_per_g(self.range_g)
        c_hi, c_lo = adxl355.temp_raw_to_c(t_min), adxl355.temp_raw_to_c(t_max)
        return Acquisition(
            mean_g=tuple(float(x) for x in mean_c / scale),  # type: ignore[arg-type]
            sd_g=tuple(float(x) for x in sd_c / scale),  # type: ignore[arg-type]
            n=n,
            sensor_c=float(adxl355.temp_raw_to_c(t_mean)),
            sensor_c_span=float(abs(c_hi - c_lo)),
            saturated=f[11] == "1",
            duration_s=self.clock.now() - t0,
        )

    async def stream_raw(self, n_samples: int) -> AsyncIterator[tuple[np.ndarray, float]]:
        """Yield ``(sample_g (3,), sensor_c)`` for each raw frame of one RAW capture."""
        counts, temps = await self._raw_counts(n_samples)
        scale = adxl355.lsb_per_g(self.range_g)
        for c, t in zip(counts, temps, strict=True):
            yield c / scale, float(adxl355.temp_raw_to_c(t))

    async def close(self) -> None:
        if self._on_close is not None:  # a channel: the bridge closes the line after the last
            on_close, self._on_close = self._on_close, None
            await on_close()
            return
        await self._line.close()

    # --- raw path ---------------------------------------------------------------
    async def _acquire_raw(self, n_samples: int) -> Acquisition:
        t0 = self.clock.now()
        counts, temps = await self._raw_counts(n_samples)
        g = counts / adxl355.lsb_per_g(self.range_g)
        temps_c = adxl355.temp_raw_to_c(temps)
        sd = g.std(axis=0, ddof=1) if len(g) > 1 else np.zeros(3)
        return Acquisition(
            mean_g=tuple(float(x) for x in g.mean(axis=0)),  # type: ignore[arg-type]
            sd_g=tuple(float(x) for x in sd),  # type: ignore[arg-type]
            n=len(g),
            sensor_c=float(temps_c.mean()),
            sensor_c_span=float(temps_c.max() - temps_c.min()),
            saturated=adxl355.is_saturated(counts, self.range_g),
            duration_s=self.clock.now() - t0,
        )

    async def _raw_counts(self, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        lines = await self._exchange(["RAW", n_samples], n_samples + 1,
                                     n_samples / self.odr_hz)
        *frames, end = lines
        if end != ["END", str(n_samples)]:
            raise ProtocolError(self.device, f"RAW capture ended with {end!r}")
        counts = np.empty((n_samples, 3), dtype=np.int64)
        temps = np.empty(n_samples)
        for i, f in enumerate(frames):
            if f[0] != "R" or len(f) != 6:
                raise ProtocolError(self.device, f"raw frame {i} malformed: {f!r}")
            try:
                counts[i] = [adxl355.counts_from_20bit(int(x, 16)) for x in f[2:5]]
                temps[i] = float(f[5])
            except ValueError:
                raise ProtocolError(self.device, f"raw frame {i} has a non-number: {f!r}") from None
        return counts, temps

    # --- transport ----------------------------------------------------------------
    async def _command(self, fields: list[object], *, expect: str, n_lines: int = 1,
                       extra_wait_s: float = 0.0) -> list[str]:
        lines = await self._exchange(fields, n_lines, extra_wait_s)
        f = lines[0]
        if f[0] != expect:
            raise ProtocolError(self.device, f"expected {expect} reply, got {f!r}")
        return f

    async def _exchange(self, fields: list[object], n_lines: int,
                        extra_wait_s: float) -> list[list[str]]:
        """Send one command, read ``n_lines`` replies (:meth:`SerialLine.call`)."""
        return await self._line.call(self._exchange_blocking, fields, n_lines, extra_wait_s)

    def _exchange_blocking(self, port: serial.SerialBase, fields: list[object], n_lines: int,
                           extra_wait_s: float) -> list[list[str]]:
        try:
            port.reset_input_buffer()
            port.write(encode_frame(*self._address, *fields, framing=self.framing))
            out: list[list[str]] = []
            pending = bytearray()
            for i in range(n_lines):
                # First line of a capture waits for the capture itself (device time).
                wait_s = self.timeout_s + (extra_wait_s if i == 0 else 0.0)
                line = read_line(port, wait_s, pending)
                if not line.endswith(b"\n"):
                    raise DeviceTimeout(self.device, f"no reply to {fields[0]} within "
                                                     f"{wait_s:.1f} s")
                f = self._reply_fields(decode_frame(line, self.device, self.framing), fields)
                if f[0] == "ERR":
                    raise self._err_fault(f, fields)
                out.append(f)
            return out
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(self.device, f"{self.url}: {exc}") from exc

    def _reply_fields(self, f: list[str], fields: list[object]) -> list[str]:
        """A reply line's fields without its channel address, which must be ours.

        Data from another channel (a late reply on a shared port, a bridge bug) must never
        pass as this sensor's, so any other address, or none on an addressed command, is a
        :class:`ProtocolError`. One exception: an unaddressed ``ERR`` answering an addressed
        command is the bridge refusing it (no data to mistake; a bridge without channel
        addressing says ``ERR 1 unknown command @1``), so it keeps its ``ERR`` meaning.
        """
        channel, rest = split_channel(f, self.device)
        if channel == self.channel:
            return rest
        if channel is None and rest[0] == "ERR":
            return rest
        said = "no channel address" if channel is None else f"channel {channel}"
        want = "no channel (an unaddressed command)" if self.channel is None else \
            f"channel {self.channel}"
        raise ProtocolError(self.device, f"reply to {fields[0]} carries {said}, expected "
                                         f"{want}: {','.join(f)[:60]!r}")

    def _err_fault(self, f: list[str], fields: list[object]) -> DeviceFault:
        """An ``ERR,<code>,<text>`` reply → the fault class its code means."""
        code = int(f[1]) if len(f) > 1 and f[1].isdigit() else None
        text = ",".join(f[2:]) or "error"
        command = ",".join(str(x) for x in (*self._address, *fields))
        if code == ERR_BAD_FRAME:
            return ProtocolError(self.device, f"bridge received {command!r} garbled: {text}")
        if code in _PERMANENT_ERRS:
            hint = ""
            if code == ERR_UNKNOWN_COMMAND and self._address and CHANNEL_MARK in text:
                hint = (" (this bridge has no channel addressing: a one-sensor bridge is "
                        "declared without 'channels')")
            return ConfigurationFault(self.device, f"bridge refuses {command!r}: ERR {code} "
                                                   f"{text}{hint}", code)
        return ExceptionReply(self.device, f"ERR {code} {text}", code)


class MultiplexedBridge:
    """One bridge port hosting several sensors, one per channel (docs/sensor-bridge.md).

    The channels share one :class:`SerialLine`, so one command is in flight on the port.
    Each :meth:`channel` handle is a full :class:`SerialAccelerometer` with its own range,
    ODR, timeout and faults: a channel that times out or is refused fails that handle's
    call only. The port closes once every handle taken has been closed (or on
    :meth:`close`).

    Averaged captures are grouped: the ``acquire(n)`` calls of several channels that
    arrive in one event-loop turn (the engine's ``sensors.read_all`` starts a position's
    reads together) with the same ``n`` become one group command
    ``AVG,<n>,@<ch>,…``, which the bridge captures at once (:meth:`avg_fields`): eight
    sensors on one bridge cost one capture time, not eight. Each channel still gets its
    own reply line, so its fault (an ``ERR`` line, a missing or duplicated line) is its
    own. A bridge whose firmware predates the group command (2.1 answers ``ERR 1``) is
    read one channel after the other from then on, said once in the log.
    """

    def __init__(self, url: str, clock: Clock, *, baudrate: int = 115200,
                 timeout_s: float = 2.0, attempts: int = 1, device: str = "sensor",
                 framing: Framing = "v2") -> None:
        self.url, self.clock, self.framing = url, clock, framing
        self.baudrate, self.timeout_s, self.device = baudrate, timeout_s, device
        self.line = SerialLine(url, clock, baudrate=baudrate, timeout_s=timeout_s,
                               attempts=attempts, device=device, name=f"bridge {url}")
        self._open: set[int] = set()
        #: False once the firmware refused the group command: per-channel captures for good.
        self.group_capture = True
        self._forming: dict[int, _Group] = {}  # n → the group being formed this loop turn
        self._running: set[asyncio.Task[None]] = set()

    def channel(self, channel: int, *, device: str | None = None,
                mode: AcquireMode = "average") -> SerialAccelerometer:
        """The sensor on ``channel`` (``ValueError`` outside 0…99, or taken twice)."""
        channel_field(channel)
        if channel in self._open:
            raise ValueError(f"{self.url}: channel {channel} is already in use")
        self._open.add(channel)

        async def release() -> None:
            self._open.discard(channel)
            if not self._open:
                await self.line.close()

        return SerialAccelerometer(self.url, self.clock, mode=mode, baudrate=self.baudrate,
                                   timeout_s=self.timeout_s, attempts=self.line.attempts,
                                   device=device or f"{self.device} @{channel}",
                                   framing=self.framing, channel=channel, line=self.line,
                                   on_close=release, group=self.avg_fields)

    async def channels(self) -> dict[int, str]:
        """``CHANNELS`` → ``{channel: serial in its fixture EEPROM ("" when blank)}``."""
        f = await self._bridge_handle()._command(["CHANNELS"], expect="CHANNELS")
        try:
            n = int(f[1])
        except (IndexError, ValueError):
            raise ProtocolError(self.device, f"CHANNELS reply malformed: {f!r}") from None
        pairs = f[2:]
        if len(pairs) != 2 * n or not all(ch.isdigit() for ch in pairs[::2]):
            raise ProtocolError(self.device, f"CHANNELS reply lists {len(pairs)} fields for "
                                             f"{n} channels, expected {2 * n}: {f!r}")
        return {int(ch): serial for ch, serial in zip(pairs[::2], pairs[1::2], strict=True)}

    async def avg_fields(self, handle: SerialAccelerometer, n_samples: int) -> list[str]:
        """``handle``'s ``AVG`` reply fields, captured with whichever other channels ask for
        ``n`` samples in the same event-loop turn (at any ODR: the group paces at the slowest).

        The window is one turn of the loop (``call_soon``), not a wall-time wait: the reads
        ``sensors.read_all`` starts together all reach here before the group is sent, and a
        lone call (a retry, a one-sensor read) goes out as its own ``@<ch>,AVG,<n>``.
        """
        group = self._forming.get(n_samples)
        if not self.group_capture or handle.channel is None or \
                (group is not None and handle.channel in group.members):
            return await handle.avg_fields(n_samples)  # (a second call of one handle: queued)
        loop = asyncio.get_running_loop()
        if group is None:
            group = self._forming[n_samples] = _Group(n_samples)
            loop.call_soon(self._launch, n_samples)
        reply: asyncio.Future[list[str]] = loop.create_future()
        group.members[handle.channel] = (handle, reply)
        try:
            return await reply
        except asyncio.CancelledError:
            if group.task is None:  # not sent yet: it goes without this channel
                group.members.pop(handle.channel, None)
            elif all(f.done() for _h, f in group.members.values()):
                group.task.cancel()  # nobody waits for it any more (its port is closed)
            raise

    async def close(self) -> None:
        self._open.clear()
        await self.line.close()

    # --- group capture ------------------------------------------------------------------
    def _bridge_handle(self) -> SerialAccelerometer:
        """An unaddressed handle on the shared line, for the bridge's own commands."""
        return SerialAccelerometer(self.url, self.clock, timeout_s=self.timeout_s,
                                   device=self.device, framing=self.framing, line=self.line)

    def _launch(self, n_samples: int) -> None:
        group = self._forming.pop(n_samples)
        if group.members:
            group.task = asyncio.ensure_future(self._capture(group))
            self._running.add(group.task)
            group.task.add_done_callback(self._running.discard)

    async def _capture(self, group: _Group) -> None:
        """Run one group and hand each member its reply fields or its own fault."""
        members = {ch: h for ch, (h, _f) in group.members.items()}
        outcomes: dict[int, list[str] | DeviceFault]
        try:
            if len(members) == 1:
                outcomes = {ch: await _outcome(h.avg_fields(group.n))
                            for ch, h in members.items()}
            else:
                try:
                    outcomes = await self.line.call(self._group_blocking, members, group.n)
                except _GroupRefused as refused:
                    self.group_capture = False
                    log.warning("%s: bridge %s refuses the group capture (%s): its channels "
                                "are read one after the other from now on (firmware older "
                                "than soakcal-fw-2.2)", self.device, self.url, refused)
                    outcomes = {ch: await _outcome(h.avg_fields(group.n))
                                for ch, h in members.items()}
                except DeviceFault as fault:  # the whole command failed: each member's fault
                    outcomes = {ch: _member_fault(fault, h.device) for ch, h in members.items()}
        except BaseException:
            for _h, f in group.members.values():
                f.cancel()
            raise
        for ch, (_h, f) in group.members.items():
            if f.done():
                continue
            outcome = outcomes[ch]
            if isinstance(outcome, DeviceFault):
                f.set_exception(outcome)
            else:
                f.set_result(outcome)

    def _group_blocking(self, port: serial.SerialBase, members: dict[int, SerialAccelerometer],
                        n: int) -> dict[int, list[str] | DeviceFault]:
        """Send ``AVG,<n>,@<ch>,…``; read the lines up to ``END,AVG,<k>``; sort them by address.

        A line that fails its CRC or has no known address is set aside (its channel then
        finds no line: a ProtocolError for that channel alone). An unaddressed ``ERR`` first
        line refuses the whole command (ERR 1: :class:`_GroupRefused`). No ``END`` within
        the timeout: the channels whose lines came deliver, the others time out, and the
        port is closed (its stream position is unknown).
        """
        timeout_s = max(h.timeout_s for h in members.values())
        capture_s = max(n / h.odr_hz for h in members.values())  # paced by the slowest ODR
        command = ["AVG", n, *(channel_field(ch) for ch in members)]
        got: dict[int, list[list[str]]] = {ch: [] for ch in members}
        unusable: list[str] = []  # why a line could not be given to a channel
        try:
            port.reset_input_buffer()
            port.write(encode_frame(*command, framing=self.framing))
            pending = bytearray()
            for i in range(2 * len(members) + 4):  # a bridge that never says END ends here
                # The first line waits for the capture itself (device time).
                wait_s = timeout_s + (capture_s if i == 0 else 0.0)
                line = read_line(port, wait_s, pending)
                if not line.endswith(b"\n"):
                    port.close()
                    return {ch: _group_line(members[ch], lines, n, unusable) if lines else
                            DeviceTimeout(members[ch].device, f"no reply line in the group "
                                                              f"capture AVG,{n} within "
                                                              f"{wait_s:.1f} s")
                            for ch, lines in got.items()}
                try:
                    channel, rest = split_channel(decode_frame(line, self.device, self.framing),
                                                  self.device)
                except ProtocolError as exc:
                    unusable.append(exc.message)
                    continue
                if channel in got:
                    got[channel].append(rest)
                elif channel is None and rest[0] == "END":
                    said = ",".join(rest)
                    if rest[:2] != ["END", "AVG"]:
                        unusable.append(f"group ended with {said!r}")
                    return {ch: _group_line(members[ch], lines, n, unusable)
                            for ch, lines in got.items()}
                elif channel is None and rest[0] == "ERR" and i == 0:
                    raise self._command_refusal(rest, command)
                else:
                    whose = "no channel" if channel is None else f"channel {channel}"
                    unusable.append(f"a line for {whose} not asked: {','.join(rest)[:40]!r}")
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(self.device, f"{self.url}: {exc}") from exc
        raise ProtocolError(self.device, f"group capture AVG,{n}: no END after "
                                         f"{2 * len(members) + 4} lines")

    def _command_refusal(self, f: list[str], command: list[object]) -> Exception:
        fault = self._bridge_handle()._err_fault(f, command)
        if isinstance(fault, ConfigurationFault) and fault.code == ERR_UNKNOWN_COMMAND:
            return _GroupRefused(fault.message)
        return fault


class _Group:
    """The averaged captures of one bridge's channels asked for in one loop turn."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.members: dict[int, tuple[SerialAccelerometer, asyncio.Future[list[str]]]] = {}
        self.task: asyncio.Task[None] | None = None


class _GroupRefused(Exception):
    """The bridge answered the group command ERR 1 (unknown command): older firmware."""


async def _outcome(call: Awaitable[list[str]]) -> list[str] | DeviceFault:
    try:
        return await call
    except DeviceFault as fault:
        return fault


def _group_line(handle: SerialAccelerometer, lines: list[list[str]], n: int,
                unusable: list[str]) -> list[str] | DeviceFault:
    """A channel's one line of a group capture → its ``AVG`` fields, or that channel's fault."""
    if len(lines) == 1:
        f = lines[0]
        if f[0] == "ERR":
            return handle._err_fault(f, ["AVG", n])
        if f[0] != "AVG":
            return ProtocolError(handle.device, f"expected AVG reply, got {f!r}")
        return f
    if lines:  # which one is this channel's? neither can be trusted
        return ProtocolError(handle.device, f"group capture AVG,{n}: {len(lines)} reply lines "
                                            f"for channel {handle.channel}, expected one")
    why = f" ({'; '.join(unusable)[:120]})" if unusable else ""
    return ProtocolError(handle.device, f"group capture AVG,{n}: no reply line for channel "
                                        f"{handle.channel}{why}")


def _member_fault(fault: DeviceFault, device: str) -> DeviceFault:
    """A fault of the whole group command, as one member channel's own (its device name)."""
    if isinstance(fault, ExceptionReply):
        copy: DeviceFault = type(fault)(device, fault.message, fault.code)
    else:
        copy = type(fault)(device, fault.message)
    copy.__cause__ = fault
    return copy


def read_line(port: serial.SerialBase, timeout_s: float, pending: bytearray) -> bytes:
    """The next ``\n``-terminated line within ``timeout_s`` of wall time, or what arrived of
    it (no ``\n`` at the end: the timeout).

    What has arrived is read in one go, not a byte at a time: pyserial's ``read_until``
    calls ``read(1)`` per byte, a ``select`` and a ``recv`` (or ``read``) each, which made
    every 90-byte ``AVG`` reply cost ~180 system calls and as many GIL hand-overs. The bytes
    after the line stay in ``pending`` for the exchange's next line; what is left there when
    the exchange ends is what ``reset_input_buffer`` would have discarded before the next
    command. The wait for the first byte blocks as before (``port.timeout``), marked as a
    wait for the device (:func:`drivers.clock.awaiting_device`: a simulated bridge needs
    simulated time to pass to answer); the rest is taken with a zero timeout (whatever is
    there, no waiting).
    """
    deadline = time.monotonic() + timeout_s
    while True:
        end = pending.find(b"\n")
        if end >= 0:
            line = bytes(pending[:end + 1])
            del pending[:end + 1]
            return line
        left_s = deadline - time.monotonic()
        if left_s <= 0:
            break
        port.timeout = left_s
        with awaiting_device(functools.partial(_has_input, port)):
            first = port.read(1)
        if not first:
            break
        pending += first
        port.timeout = 0
        pending += port.read(_CHUNK_BYTES)
    line = bytes(pending)
    pending.clear()
    return line


_CHUNK_BYTES = 4096  # per read of what has arrived (a longer reply: the next round takes the rest)


def _has_input(port: serial.SerialBase) -> bool:
    """Bytes have arrived on ``port`` that its reader has yet to take (a virtual clock's
    look while the reader waits: :func:`drivers.clock.awaiting_device`)."""
    return bool(port.in_waiting)


def open_serial_port(url: str, baudrate: int, timeout_s: float,
                     device: str) -> serial.SerialBase:
    """A pyserial port for ``url`` (a device path or any ``serial_for_url`` URL); a port
    that cannot be opened is :class:`ConnectionLost` naming the URL (the guard retries it).
    Shared by the framed bridge and the plain stream driver."""
    try:
        return serial.serial_for_url(url, baudrate=baudrate, timeout=timeout_s)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise ConnectionLost(device, f"cannot open {url}: {exc}") from exc
