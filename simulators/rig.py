"""One call to start a whole simulated rig (chamber, table, sensor bridges) on loopback.

The campaign engine's tests and ``soakcal demo`` use::

    async with start_sim_rig(clock, seed=1) as rig:
        chamber, table, sensor = await connect_rig(rig, clock)
        ...

A fixture of several sensors (issue 12): ``start_sim_rig(clock, seed=1,
serials=["SN-1", "SN-2"])`` mounts one simulated bridge per serial, all in the
same chamber and on the same table, each with its own truth drawn from
:func:`sensor_seed` of its serial (so a serial is the same part in every run)
and its own noise stream; :func:`connect_sensors` opens a driver per bridge.
``truths={serial: truth}`` replaces the part of the serials it names (a benchmark's
truth with keyed noise or an extra effect); the others keep their serial's part.
``multiplexed=True`` mounts those sensors behind one multiplexing bridge instead, channel
``i`` for the ``i``-th serial, on one port (docs/sensor-bridge.md, "Channels"); each keeps
its own part, noise stream, identity and faults, and :func:`connect_sensors` opens one
channel handle per sensor over that port's one line.
"""

from __future__ import annotations

import contextlib
import itertools
import zlib
from collections.abc import AsyncIterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.thermal_plant import AMBIENT_C
from drivers.chamber import ModbusChamber
from drivers.clock import Clock
from drivers.modbus_link import ModbusLink, RetryPolicy
from drivers.registermaps import load_chamber_map, load_turntable_map
from drivers.sensor_bridge import MultiplexedBridge, SerialAccelerometer
from drivers.turntable import ModbusTurntable
from simulators.bridge_sim import (
    BridgeDevice,
    BridgeServer,
    MultiplexedBridgeDevice,
    start_bridge_server,
)
from simulators.chamber_sim import ChamberPhysics, ChamberRegisterImage, ControllerSetup
from simulators.faults import SimFaults
from simulators.modbus_server import IN_MEMORY_HOST, ModbusSimServer, start_modbus_server
from simulators.turntable_sim import TurntablePhysics, TurntableRegisterImage, drive_images

# Null-modem "ports" are names inside this process; hand out fresh ones per rig.
_in_memory_ports = itertools.count(47000, 2)


@dataclass
class RigFaults:
    """Fault switches per device; mutate while the rig runs."""

    chamber: SimFaults = field(default_factory=SimFaults)
    table: SimFaults = field(default_factory=SimFaults)
    sensor: SimFaults = field(default_factory=SimFaults)


def sensor_seed(serial: str) -> int:
    """The truth seed of a simulated sensor: a stable function of its serial (CRC-32).

    ``hash()`` is salted per process; CRC-32 gives the same part in every run.
    """
    return zlib.crc32(serial.encode("utf-8"))


@dataclass
class SimSensor:
    """One mounted simulated sensor: its serial, bridge physics, server and faults.

    ``channel``: its channel on the rig's multiplexing bridge (``server`` is then shared by
    every sensor of the rig); ``None`` on a bridge of its own.
    """

    serial: str
    bridge: BridgeDevice
    server: BridgeServer
    faults: SimFaults
    channel: int | None = None

    @property
    def url(self) -> str:  # socket://127.0.0.1:PORT
        return self.server.url


@dataclass
class SimRig:
    """A running simulated rig: physics objects, servers and their addresses."""

    chamber_map: str  # a shipped map name or a map file path (drivers/registermaps.py)
    chamber: ChamberPhysics
    table: TurntablePhysics
    bridge: BridgeDevice
    faults: RigFaults
    chamber_server: ModbusSimServer
    table_server: ModbusSimServer
    bridge_server: BridgeServer
    table_map: str = "soakcal-table"
    # Every mounted sensor when started with ``serials`` (the first is ``bridge``); else empty.
    sensors: list[SimSensor] = field(default_factory=list)

    @property
    def chamber_url(self) -> str:  # tcp://127.0.0.1:PORT
        return self.chamber_server.url

    @property
    def table_url(self) -> str:  # tcp://127.0.0.1:PORT
        return self.table_server.url

    @property
    def sensor_url(self) -> str:  # socket://127.0.0.1:PORT
        return self.bridge_server.url

    @property
    def multiplexed(self) -> bool:
        """The sensors share one multiplexing bridge (``start_sim_rig(multiplexed=True)``)."""
        return any(s.channel is not None for s in self.sensors)

    async def stop(self) -> None:
        for extra in self.sensors[1:]:
            if extra.server is not self.bridge_server:
                await extra.server.stop()
        await self.bridge_server.stop()
        await self.table_server.stop()
        await self.chamber_server.stop()


@contextlib.asynccontextmanager
async def start_sim_rig(
    clock: Clock,
    *,
    seed: int,
    truth: Any = None,
    chamber_map: str = "eurotherm3216",
    faults: RigFaults | None = None,
    ports: int | tuple[int, int, int] = 0,
    host: str = "127.0.0.1",
    n_axes: int = 3,
    die_tau_s: float = 900.0,
    start_c: float = AMBIENT_C,
    modbus_in_memory: bool = False,
    table_map: str = "soakcal-table",
    serials: Sequence[str] = (),
    truths: Mapping[str, Any] | None = None,
    multiplexed: bool = False,
    controller: ControllerSetup | None = None,
) -> AsyncIterator[SimRig]:
    """Start chamber, table and bridge servers; ``ports=0`` means ephemeral ports.

    ``serials`` of two or more mounts one bridge per serial (module docstring; the
    extra bridges listen on ephemeral ports); ``truth`` and ``seed`` then only set
    the chamber's and table's streams. One serial or none: the one-sensor rig as before.
    ``truths`` (several serials only): the truth of each serial it names, instead of
    the serial's own part; a serial it names that is not mounted is a ``ValueError``.
    ``multiplexed`` (several serials): all of them on one multiplexing bridge, serial ``i``
    on channel ``i`` (module docstring); ignored for one sensor or none.

    ``ports`` may be one base port (chamber, base+1 table, base+2 sensor) or a
    triple. ``truth`` defaults to ``SensorTruth.adxl355_typical(seed)``.
    ``modbus_in_memory=True`` serves chamber and table over pymodbus' in-process
    null modem instead of TCP (about 2× faster; the sensor bridge stays on TCP).
    ``controller``: how the chamber controller is set up (decimal point, units, ramp
    units, word order, silent registers, mode); default: exactly as the map says.
    """
    rig = await _start(clock, seed=seed, truth=truth, chamber_map=chamber_map,
                       faults=faults, ports=ports, host=host, n_axes=n_axes,
                       die_tau_s=die_tau_s, start_c=start_c, modbus_in_memory=modbus_in_memory,
                       table_map=table_map, serials=serials, truths=truths,
                       multiplexed=multiplexed, controller=controller)
    try:
        yield rig
    finally:
        await rig.stop()


async def connect_rig(
    sim_rig: SimRig, clock: Clock, *, policy: RetryPolicy | None = None,
    sensor_mode: str = "average",
) -> tuple[ModbusChamber, ModbusTurntable, SerialAccelerometer]:
    """Driver instances talking to ``sim_rig`` over its real loopback sockets."""
    chamber = ModbusChamber(
        ModbusLink(sim_rig.chamber_url, clock, device="chamber", policy=policy),
        load_chamber_map(sim_rig.chamber_map),
    )
    table = ModbusTurntable(
        ModbusLink(sim_rig.table_url, clock, device="turntable", policy=policy),
        load_turntable_map(sim_rig.table_map), n_axes=sim_rig.table.n_axes,
    )
    sensor = SerialAccelerometer(sim_rig.sensor_url, clock, mode=sensor_mode)  # type: ignore[arg-type]
    return chamber, table, sensor


def connect_sensors(sim_rig: SimRig, clock: Clock, *,
                    sensor_mode: str = "average") -> dict[str, SerialAccelerometer]:
    """A bridge driver per mounted sensor, by serial (rigs started with ``serials``);
    on a multiplexed rig, a channel handle each over the one bridge's shared line."""
    if sim_rig.multiplexed:
        bridge = MultiplexedBridge(sim_rig.sensor_url, clock)
        return {s.serial: bridge.channel(s.channel or 0, mode=sensor_mode)  # type: ignore[arg-type]
                for s in sim_rig.sensors}
    return {s.serial: SerialAccelerometer(s.url, clock, mode=sensor_mode)  # type: ignore[arg-type]
            for s in sim_rig.sensors}


async def _start(clock: Clock, *, seed: int, truth: Any, chamber_map: str,
                 faults: RigFaults | None, ports: int | tuple[int, int, int], host: str,
                 n_axes: int, die_tau_s: float, start_c: float,
                 modbus_in_memory: bool = False, table_map: str = "soakcal-table",
                 serials: Sequence[str] = (),
                 truths: Mapping[str, Any] | None = None,
                 multiplexed: bool = False,
                 controller: ControllerSetup | None = None) -> SimRig:
    # Any map file: the twin renders whatever layout the map describes (MapError if unusable).
    chamber_regmap = load_chamber_map(chamber_map)
    table_regmap = load_turntable_map(table_map)
    n_axes = min(n_axes, table_regmap.n_axes)  # the twin's table has the map's axes at most
    several = len(serials) > 1
    truths = dict(truths or {})
    if truths and not several:
        raise ValueError("truths: only a rig of several serials takes a truth per serial")
    unknown = sorted(set(truths) - set(serials))
    if unknown:
        raise ValueError(f"truths name serials not mounted: {', '.join(unknown)}")
    if several:
        truth = truths.get(serials[0])
        truth = _serial_truth(serials[0]) if truth is None else truth
    elif truth is None:
        from simulators.truth import SensorTruth  # the physics dependency, loaded late

        truth = SensorTruth.adxl355_typical(seed)
    faults = faults or RigFaults()
    if isinstance(ports, int):
        port_c, port_t, port_s = (ports, ports + 1, ports + 2) if ports else (0, 0, 0)
    else:
        port_c, port_t, port_s = ports
    # Independent streams per device so fault draws never shift the sensor noise.
    rng_c, rng_t, rng_s, rng_pv = (np.random.default_rng(s)
                                   for s in np.random.SeedSequence(seed).spawn(4))
    chamber = ChamberPhysics(clock, rng_pv, air_c=start_c, setpoint_c=start_c,
                             ambient_c=start_c, die_tau_s=die_tau_s, faults=faults.chamber)
    table = TurntablePhysics(clock, n_axes=n_axes, faults=faults.table,
                             homed_at_start="home" not in table_regmap.sequences,
                             settled_at_start=bool(table_regmap.unit_ids))

    die_now, die_motion = chamber.die_now_c, chamber.die_motion_now
    bridge = BridgeDevice(truth, clock, rng_s, die_now, table.true_angles_deg,
                          faults=faults.sensor, die_motion=die_motion)
    modbus_host = host
    if modbus_in_memory:
        modbus_host = IN_MEMORY_HOST
        port_c = next(_in_memory_ports)
        port_t = port_c + 1
    cs = await start_modbus_server(ChamberRegisterImage(chamber, chamber_regmap,
                                                        setup=controller),
                                   faults.chamber, rng_c, host=modbus_host, port=port_c)
    # A drive per axis (the map's unit_ids): each axis its own unit id on one server.
    table_image: Any = (drive_images(table, table_regmap) if table_regmap.unit_ids
                        else TurntableRegisterImage(table, table_regmap))
    ts = await start_modbus_server(table_image,
                                   faults.table, rng_t, host=modbus_host, port=port_t)
    if several and multiplexed:
        return await _start_multiplexed(clock, serials, seed, truths, bridge, die_now, table,
                                        host, port_s,
                                        SimRig(chamber_map, chamber, table, bridge, faults, cs,
                                               ts, None, table_map))  # type: ignore[arg-type]
    bs = await start_bridge_server(bridge, host=host, port=port_s)
    rig = SimRig(chamber_map, chamber, table, bridge, faults, cs, ts, bs, table_map)
    if several:
        rig.sensors.append(SimSensor(serials[0], bridge, bs, faults.sensor))
        try:
            for i, serial in enumerate(serials[1:], start=2):
                rig.sensors.append(await _start_sensor(clock, serial, i, seed, die_now,
                                                       table, host, truths.get(serial),
                                                       die_motion))
        except BaseException:
            await rig.stop()
            raise
    return rig


async def _start_multiplexed(clock: Clock, serials: Sequence[str], seed: int,
                             truths: Mapping[str, Any], first: BridgeDevice, die_now: Any,
                             table: TurntablePhysics, host: str, port: int,
                             rig: SimRig) -> SimRig:
    """Every serial on one multiplexing bridge: serial ``i`` on channel ``i``, one port.

    Channel 0 is the first serial's device (the rig's ``bridge``, with the rig's sensor
    faults); the others are built as the bridges of :func:`_start_sensor` would be (their
    own part, noise stream and faults), without a server each. They share one board uid.
    """
    devices = [first]
    for serial in serials[1:]:
        devices.append(_sensor_device(clock, serial, seed, die_now, table,
                                      truths.get(serial), first.board_uid, first.die_motion))
    mux = MultiplexedBridgeDevice(dict(enumerate(devices)))
    try:
        server = await start_bridge_server(mux, host=host, port=port)
    except BaseException:
        await rig.table_server.stop()
        await rig.chamber_server.stop()
        raise
    rig.bridge_server = server
    rig.sensors = [SimSensor(serial, dev, server, dev.faults, channel=ch)
                   for ch, (serial, dev) in enumerate(zip(serials, devices, strict=True))]
    return rig


def _serial_truth(serial: str) -> Any:
    """The simulated part a serial stands for (the same in every run: :func:`sensor_seed`)."""
    from simulators.truth import SensorTruth  # the physics dependency, loaded late

    return SensorTruth.adxl355_typical(sensor_seed(serial), serial=serial)


async def _start_sensor(clock: Clock, serial: str, index: int, seed: int, die_now: Any,
                        table: TurntablePhysics, host: str, truth: Any = None,
                        die_motion: Any = None) -> SimSensor:
    """The ``index``-th bridge of a fixture: its own truth, noise stream, faults and port.

    ``truth``: an injected truth for this serial; default the serial's own part.
    """
    bridge = _sensor_device(clock, serial, seed, die_now, table, truth,
                            f"SIM-BRIDGE-{index:04d}", die_motion)
    server = await start_bridge_server(bridge, host=host, port=0)
    return SimSensor(serial, bridge, server, bridge.faults)


def _sensor_device(clock: Clock, serial: str, seed: int, die_now: Any,
                   table: TurntablePhysics, truth: Any, board_uid: str,
                   die_motion: Any = None) -> BridgeDevice:
    """One extra sensor's simulated device: its part, its noise stream, its own faults."""
    # Noise differs per sensor and per campaign seed; the part is its serial's unless injected.
    rng = np.random.default_rng(np.random.SeedSequence([seed, sensor_seed(serial)]))
    return BridgeDevice(_serial_truth(serial) if truth is None else truth, clock, rng,
                        die_now, table.true_angles_deg, faults=SimFaults(),
                        board_uid=board_uid, die_motion=die_motion)
