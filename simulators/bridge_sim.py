"""Simulated sensor bridge: the serial line protocol served on a TCP socket.

Reachable as ``socket://127.0.0.1:PORT`` through ``serial.serial_for_url``.
Samples come from the sensor truth model at the die temperature of the
simulated chamber (the die lags the air, see :class:`ChamberPhysics`) and the
orientation of the simulated table (:mod:`drivers.geometry`).

:class:`BridgeDevice` is a one-sensor bridge as flashed before channel addressing
(``@1,ID`` is an unknown command to it). :class:`MultiplexedBridgeDevice` hosts several
of them, one per channel, behind one port (docs/sensor-bridge.md, "Channels"): each
keeps its own part, noise stream, identity and faults, and its group capture
``AVG,<n>,@<ch>,…`` reads the listed channels in one capture's time.
"""

from __future__ import annotations

import asyncio
import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers import adxl355
from drivers.bridge_protocol import Framing, channel_field, encode_frame, parse_frame, split_channel
from drivers.clock import Clock
from drivers.faults import ProtocolError
from drivers.geometry import reference_for_angles, rotation_for_angles
from simulators.faults import SimFaults
from simulators.line_server import LineServer, start_line_server

FIRMWARE = "soakcal-sim-2.0"
_NO_FAULTS = SimFaults()
#: The simulated ADXL355's id registers (datasheet: DEVID_AD, DEVID_MST, PARTID, REVID).
PART_IDS = (adxl355.DEVID_AD, adxl355.DEVID_MST, adxl355.PARTID, adxl355.REVID_SIM)


@dataclass(frozen=True)
class Route:
    """Where one received command goes: the address its replies carry, the channel's device
    (whose faults apply; ``None`` for a bridge-level reply) and the command's own fields."""

    address: list[str]
    target: BridgeDevice | None
    command: list[str]
    refusal: list[object] | None = None  # the bridge's own answer instead of the device's
    group: list[int] | None = None  # a group capture's channels (AVG,<n>,@<ch>,…)


@dataclass
class BridgeDevice:
    """Device-side state and sample generation, independent of the socket.

    ``die_c`` and ``angles_deg`` are callables so the bridge always sees the
    current simulated chamber and table (each advances its physics on call).
    """

    truth: Any  # simulators.truth.SensorTruth (duck-typed: sample_g, odr_hz, range_g, serial)
    clock: Clock
    rng: np.random.Generator
    die_c: Callable[[], float]
    angles_deg: Callable[[], tuple[float, ...]]
    g_local: float = 1.0
    faults: SimFaults = field(default_factory=SimFaults)
    max_samples: int = 100_000
    board_uid: str = "SIM-BRIDGE-0001"
    part_ids: tuple[int, int, int, int] = PART_IDS
    #: The simulated fixture EEPROM; ``None`` reports the truth model's serial.
    eeprom_serial: str | None = None
    #: The die's (dT/dt °C/s, last excursion's direction) now, for a truth whose effects
    #: act on them (rate sensitivity, hysteresis); ``None``: a die at rest, never moved.
    die_motion: Callable[[], tuple[float, int]] | None = None

    def reference_g(self) -> np.ndarray:
        return _reference(tuple(self.angles_deg()), self.g_local)

    async def capture(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Wait the capture time on the clock, then return (counts (n,3), temp raw (n,))."""
        await self.clock.sleep(n / self.truth.odr_hz)
        die_c = self.die_c()
        angles = tuple(self.angles_deg())
        ref = _reference(angles, self.g_local)
        g = self.truth.sample_g(ref, die_c, n, self.rng, t_s=self.clock.now(),
                                lab_to_sensor=_pose(angles), **self._motion())
        counts = adxl355.g_to_counts(g, self.truth.range_g)
        temps_c = _temperature_samples(self.truth, die_c, n, self.rng)
        return counts, adxl355.temp_c_to_raw(temps_c)

    def _motion(self) -> dict[str, float | int]:
        """The die's motion for ``sample_g``, where the truth has effects that act on it
        (a truth without effects, such as a test's stand-in, is called as before)."""
        if self.die_motion is None or not getattr(self.truth, "effects", None):
            return {}
        rate, direction = self.die_motion()
        return {"die_rate_c_per_s": rate, "direction": direction}

    def route(self, fields: list[str]) -> Route:
        """Every command is this sensor's: "@1,ID" is an unknown command (a pre-channel bridge)."""
        return Route([], self, fields)

    async def answer(self, route: Route, framing: Framing) -> list[list[object]]:
        return await self.replies(route.command, framing)

    async def handle(self, fields: list[str], framing: Framing = "v2") -> list[bytes]:
        """One command → reply frames, in the framing the command arrived in.

        A v2 bridge answers a v1 host in v1 (and the 4-field v1 ``ID``), so
        hosts not yet updated keep working against new firmware.
        """
        return [encode_frame(*reply, framing=framing)
                for reply in await self.replies(fields, framing)]

    async def replies(self, fields: list[str], framing: Framing = "v2") -> list[list[object]]:
        cmd = fields[0]
        if cmd == "ID":
            serial = self.eeprom_serial if self.eeprom_serial is not None else \
                getattr(self.truth, "serial", "SIM")
            ident: list[object] = ["ID", "ADXL355", serial, FIRMWARE]
            if framing == "v2":
                ident += [self.board_uid, *(f"{v:02X}" for v in self.part_ids)]
            return [ident]
        if cmd == "CFG" and len(fields) == 3:
            try:
                range_g, odr_hz = float(fields[1]), float(fields[2])
                adxl355.lsb_per_g(range_g)
            except ValueError:
                return [["ERR", 3, "bad range or ODR"]]
            if odr_hz <= 0:
                return [["ERR", 3, "bad range or ODR"]]
            self.truth.range_g, self.truth.odr_hz = range_g, odr_hz
            return [["OK", "CFG", f"{range_g:g}", f"{odr_hz:g}"]]
        if cmd in ("AVG", "RAW") and len(fields) == 2 and fields[1].isdigit():
            n = int(fields[1])
            if not 1 <= n <= self.max_samples:
                return [["ERR", 3, f"n must be 1..{self.max_samples}"]]
            counts, traw = await self.capture(n)
            return _avg_reply(counts, traw, self.truth.range_g) if cmd == "AVG" else \
                _raw_reply(counts, traw)
        if cmd == "SN" and len(fields) == 2:
            if not 1 <= len(fields[1]) <= 24 or " " in fields[1]:
                return [["ERR", 3, "serial must be 1..24 characters without blanks"]]
            self.eeprom_serial = fields[1]  # the twin's fixture now names this sensor
            return [["OK", "SN", self.eeprom_serial]]
        return [["ERR", 1, f"unknown command {cmd}"]]


@dataclass
class MultiplexedBridgeDevice:
    """One bridge board, one port, a sensor per channel (its chip select on one SPI bus).

    Addressed commands (``@<ch>,…``) go to that channel's :class:`BridgeDevice` and every
    reply line carries the address back; an unaddressed command is channel 0's, answered
    unaddressed (what an old host sends and expects); ``CHANNELS`` lists the channels
    with their fixture serials. A channel with no sensor answers ``ERR 7``.
    """

    channels: dict[int, BridgeDevice]

    #: False: a bridge flashed with firmware 2.1 (channels, no group capture), which answers
    #: ``AVG,<n>,@<ch>,…`` with ERR 1 as any unknown command.
    group_capture: bool = True

    def route(self, fields: list[str]) -> Route:
        try:
            channel, command = split_channel(fields, "bridge")
        except ProtocolError as exc:
            return Route([], None, fields, ["ERR", 3, exc.message])
        if channel is None:
            if fields == ["CHANNELS"]:
                return Route([], None, fields, self._channels_reply())
            if fields[0] == "AVG" and len(fields) > 2 and self.group_capture:
                return self._group_route(fields)
            channel = 0
            address: list[str] = []
        else:
            address = [channel_field(channel)]
        device = self.channels.get(channel)
        if device is None:
            return Route(address, None, command,
                         ["ERR", 7, f"no sensor on channel {channel}"])
        return Route(address, device, command)

    async def answer(self, route: Route, framing: Framing) -> list[list[object]]:
        if route.group is not None:
            return await self.group_avg(route)
        if route.target is None:  # the bridge answers for itself (CHANNELS, ERR 3 / 7)
            return [route.refusal or ["ERR", 1, "unknown command"]]
        return await route.target.replies(route.command, framing)

    def _group_route(self, fields: list[str]) -> Route:
        """``AVG,<n>,@<ch>,…``: checked as the firmware does (one unaddressed ERR 3 for a bad
        n or channel list), else a route whose replies carry their own addresses."""
        n = int(fields[1]) if fields[1].isdigit() else 0
        max_n = min(d.max_samples for d in self.channels.values())
        if not 1 <= n <= max_n:
            return Route([], None, fields, ["ERR", 3, f"n must be 1..{max_n}"])
        group: list[int] = []
        for head in fields[2:]:
            try:
                ch, _rest = split_channel([head, "AVG"], "bridge")
            except ProtocolError:
                ch = None
            if ch is None or ch in group:
                return Route([], None, fields,
                             ["ERR", 3, f"bad or repeated channel address {head}"])
            group.append(ch)
        return Route([], None, fields, group=group)

    async def group_avg(self, route: Route) -> list[list[object]]:
        """One capture of every channel of the group, at once on the clock (the firmware
        reads each chip in turn per sample period): one addressed line per channel in the
        command's order, then ``END,AVG,<lines>``.

        Each channel keeps its own faults: its ``p_no_reply`` / ``p_drop`` loses its line
        only (the host then finds it missing), its ``p_exception`` answers its line ERR 6;
        an empty channel is ERR 7. The others deliver.
        """
        assert route.group is not None
        n = int(route.command[1])
        rows: dict[int, list[object] | None] = {}
        capturing: dict[int, BridgeDevice] = {}
        for ch in route.group:
            dev = self.channels.get(ch)
            if dev is None:
                rows[ch] = ["ERR", 7, f"no sensor on channel {ch}"]
            elif _draw(dev, dev.faults.p_drop) or _draw(dev, dev.faults.p_no_reply):
                rows[ch] = None
            elif _draw(dev, dev.faults.p_exception):
                rows[ch] = ["ERR", 6, "busy"]
            else:
                capturing[ch] = dev
        captures = await asyncio.gather(*(dev.capture(n) for dev in capturing.values()))
        for (ch, dev), (counts, traw) in zip(capturing.items(), captures, strict=True):
            rows[ch] = _avg_reply(counts, traw, dev.truth.range_g)[0]
        out: list[list[object]] = [[channel_field(ch), *row] for ch in route.group
                                   if (row := rows[ch]) is not None]
        out.append(["END", "AVG", len(out)])
        return out

    def _channels_reply(self) -> list[object]:
        out: list[object] = ["CHANNELS", len(self.channels)]
        for ch in sorted(self.channels):
            dev = self.channels[ch]
            out += [ch, dev.eeprom_serial if dev.eeprom_serial is not None else
                    getattr(dev.truth, "serial", "")]
        return out


@functools.lru_cache(maxsize=1024)
def _pose(angles_deg: tuple[float, ...]) -> np.ndarray:
    """The table's pose (Rᵀ) at these angles, once per pose (as :func:`_reference`): a tilted
    base reaches the sensor through it. Read-only (shared)."""
    R_t = rotation_for_angles(angles_deg).T
    R_t.flags.writeable = False
    return R_t


@functools.lru_cache(maxsize=1024)
def _reference(angles_deg: tuple[float, ...], g_local: float) -> np.ndarray:
    """:func:`reference_for_angles`, once per pose: a table sweep revisits its few dozen
    poses, and every sensor on the table asks for the same one at each capture. Read-only
    (the array is shared)."""
    ref = reference_for_angles(angles_deg, g_local)
    ref.flags.writeable = False
    return ref


def _draw(device: BridgeDevice, p: float) -> bool:
    """One fault draw on the channel's own stream (no draw at p = 0: the noise is unshifted)."""
    return p > 0 and device.rng.random() < p


def _temperature_samples(truth: Any, die_c: float, n: int,
                         rng: np.random.Generator) -> np.ndarray:
    if hasattr(truth, "temperature_samples_c"):
        return np.asarray(truth.temperature_samples_c(die_c, n, rng), dtype=float)
    return die_c + rng.normal(0.0, 0.1, n)


def _avg_reply(counts: np.ndarray, traw: np.ndarray, range_g: float) -> list[list[object]]:
    n = len(counts)
    mean, sd = _mean_sd(counts)
    sat = 1 if adxl355.is_saturated(counts, range_g) else 0
    return [[
        "AVG", n, *(f"{x:.3f}" for x in mean), *(f"{x:.3f}" for x in sd),
        f"{traw.mean():.2f}", int(traw.min()), int(traw.max()), sat,
    ]]


def _mean_sd(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis mean and sample sd (ddof 1; zeros for one sample) of counts (n,3), with
    the very operations of ``counts.mean(axis=0)`` and ``counts.std(axis=0, ddof=1)`` (the
    same sums in float64, in the same order: the same bits), the mean summed once."""
    n = len(counts)
    mean = np.add.reduce(counts, axis=0, dtype=np.float64) / n
    if n < 2:
        return mean, np.zeros(3)
    dev = counts - mean
    np.multiply(dev, dev, out=dev)
    return mean, np.sqrt(np.add.reduce(dev, axis=0) / (n - 1))


def _raw_reply(counts: np.ndarray, traw: np.ndarray) -> list[list[object]]:
    out: list[list[object]] = [
        ["R", i, *(f"{adxl355.counts_to_20bit(int(c)):05X}" for c in row), int(t)]
        for i, (row, t) in enumerate(zip(counts, traw, strict=True))
    ]
    out.append(["END", len(counts)])
    return out


@dataclass
class BridgeServer:
    device: BridgeDevice | MultiplexedBridgeDevice
    listener: LineServer

    @property
    def host(self) -> str:
        return self.listener.host

    @property
    def port(self) -> int:
        return self.listener.port

    @property
    def url(self) -> str:
        return f"socket://{self.host}:{self.port}"

    async def stop(self) -> None:
        await self.listener.stop()


async def start_bridge_server(device: BridgeDevice | MultiplexedBridgeDevice, *,
                              host: str = "127.0.0.1",
                              port: int = 0) -> BridgeServer:
    """Listen for bridge clients; each connection is served line by line."""
    listener = await start_line_server(functools.partial(_serve_client, device), host=host,
                                       port=port)
    return BridgeServer(device, listener)


async def _serve_client(device: BridgeDevice | MultiplexedBridgeDevice,
                        reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    while True:
        try:
            line = await reader.readline()
        except (ConnectionError, asyncio.IncompleteReadError):
            return
        except ValueError:
            # Over the stream limit without a newline: noise, not a command. readline()
            # has dropped it; answer like the firmware does and resynchronise.
            line = b"\xff\n"
        if not line:
            return
        try:
            frame = parse_frame(line, "bridge")
        except ProtocolError:
            writer.write(encode_frame("ERR", 2, "bad frame or checksum"))
            await writer.drain()
            continue
        route = device.route(frame.fields)
        # The addressed sensor's faults (a multiplexing bridge's other channels are fine).
        target = route.target
        faults = target.faults if target is not None else _NO_FAULTS
        rng = target.rng if target is not None else None
        if faults.p_drop > 0 and rng is not None and rng.random() < faults.p_drop:
            return  # caller closes the socket
        if faults.p_no_reply > 0 and rng is not None and rng.random() < faults.p_no_reply:
            continue
        if faults.p_exception > 0 and rng is not None and rng.random() < faults.p_exception:
            rows: list[list[object]] = [["ERR", 6, "busy"]]
        else:
            rows = await device.answer(route, frame.framing)
        for row in rows:  # a group capture's rows carry their own addresses (route.address [])
            writer.write(encode_frame(*route.address, *row, framing=frame.framing))
        try:
            await writer.drain()
        except ConnectionError:
            return
