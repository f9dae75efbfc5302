"""Rig row → devices: the one place that knows which drivers a rig's config means.

``open_rig(rig_config, clock)`` is an async context manager yielding
:class:`RigDevices`. Three chamber drivers exist:

* ``sim``: starts the simulated rig in this process
  (``simulators.rig.start_sim_rig``) and connects to it through the real
  drivers over loopback sockets (``simulators.rig.connect_rig``).
* ``modbus``: a real (or remote simulated) rig, reached by URL::

    {"chamber":   {"driver": "modbus", "url": "tcp://10.0.0.5:502",
                   "map": "eurotherm-3216", "device_id": 1, "range_c": [-40, 85]},
     "turntable": {"url": "tcp://10.0.0.6:502", "device_id": 1, "axes": 3,
                   "map": "soakcal-table"},
     "sensors":   [{"url": "/dev/ttyUSB0", "baudrate": 115200}],
     "time_scale": 1}

  A drive per axis on one bus (a map with ``[axes] unit_ids``, e.g.
  ``leadshine-rs485-pr``) takes the drives' ids as ``"unit_ids": [3, 4]`` (outer
  first); a 1-axis motorised stage whose second axis is set by hand is
  ``"axes": 1, "hand_axis": {"steps_deg": [0, 90, 180, 270]}`` (docs/manual-fixtures.md,
  "One motorised axis, one by hand").

  Several sensors (issue 12): one bridge per sensor, each sensor entry its own
  serial port, declaring the sensor it carries by ``serial`` (or by the values
  of its ``serials`` table, board uid → serial)::

    "sensors": [{"url": "/dev/ttyUSB0", "serial": "SN-1", "serial_binding": "eeprom"},
                {"url": "/dev/ttyUSB1", "serial": "SN-2", "serial_binding": "eeprom"}]

  Or one bridge multiplexing several sensors on one port, one sensor per channel
  (docs/sensor-bridge.md, "Channels"); the entry declares them in ``channels``::

    "sensors": [{"url": "/dev/ttyACM0", "serial_binding": "eeprom",
                 "channels": {"0": "SN-1", "1": "SN-2", "2": "SN-3"}}]

  A campaign naming several sensors opens the entry of each (and only those),
  each checked against its own entry's binding (a channel's identity is that
  channel's ``ID``). The sensors of one multiplexing entry share its port: one
  :class:`drivers.sensor_bridge.MultiplexedBridge`, a channel handle per sensor.
  Two serials behind one entry without ``channels`` are refused.

  ``url`` is ``tcp://host:port`` or ``rtu:///dev/ttyUSB0?baudrate=19200``
  (drivers/modbus_link.py); a sensor ``url`` is anything pyserial's
  ``serial_for_url`` opens (a device, ``socket://host:port``, ``rfc2217://``).
  ``map`` is a shipped register map (``drivers/maps/``) or the path of a map
  file on the service's machine (docs/registers.md). ``time_scale`` (on the
  chamber config) is how fast the rig's time runs
  against the wall clock: 1 for hardware, the ``--speed`` of a remote
  ``soakcal sim``.
* ``espec``: an ESPEC P-300 / SCP-220 over its ASCII protocol (drivers/espec_chamber.py,
  docs/chambers.md); the turntable and sensors as for ``modbus``::

    {"chamber": {"driver": "espec", "url": "/dev/ttyUSB1", "baudrate": 9600,
                 "range_c": [-40, 85], "safe_setpoint_c": 23, "safe_stop": false}, ...}

:func:`rig_config_errors` checks a config before it is stored (the API's 422).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.clock import Clock
from drivers.protocols import Accelerometer, Chamber, Turntable
from service.engine.identity import SerialBinding, binding_for_rig

AnglesFor = Callable[[np.ndarray], tuple[float, ...]]
# Commanded table angles → the pose's unit quaternion (qw, qx, qy, qz), sensor → lab.
PoseFor = Callable[[tuple[float, ...]], tuple[float, float, float, float]]


@dataclass
class RigDevices:
    chamber: Chamber
    turntable: Turntable
    accelerometer: Accelerometer
    # Maps a scheduled gravity direction (sensor frame, unit) to table angles: rig geometry.
    angles_for: AnglesFor
    # How the campaign's serial is checked against the connected sensor (identity.py):
    # "any" for the twin, which mounts whatever sensor a campaign names.
    serial_binding: SerialBinding = field(default_factory=lambda: SerialBinding("any"))
    # Every mounted sensor by serial when the rig was opened for several (``serials``);
    # ``accelerometer`` is then the first of them. Empty for a one-sensor rig.
    accelerometers: dict[str, Accelerometer] = field(default_factory=dict)
    # A real rig's several sensors: each sensor entry's own binding, by serial (else
    # ``serial_binding`` applies).
    bindings: dict[str, SerialBinding] = field(default_factory=dict)
    # The rotation the commanded angles put the sensor in (the geometry of ``angles_for``),
    # recorded with every measurement (``pose_q*``, docs/recording.md): a reader can then
    # test a rotation fixed in the lab frame, which ``ref_*`` alone cannot show. None where
    # the pose is not known: a hand-placed fixture is asked for a direction only (its
    # heading about gravity is the operator's), and a rig whose geometry is not
    # drivers/geometry.py's convention.
    pose_for: PoseFor | None = None


@asynccontextmanager
async def open_rig(
    rig: dict[str, Any], clock: Clock, *, seed: int = 0, faults: Any = None,
    sim_options: dict[str, Any] | None = None, serials: Sequence[str] = (),
    placement_sf: Any = None,
) -> AsyncIterator[RigDevices]:
    """Devices for a rig config ``{"name", "chamber", "turntable", "sensors"}``.

    ``placement_sf``: the session factory of the placement board of a hand axis (default:
    the service's database).

    ``serials``: the sensors a campaign names; the ``sim`` twin mounts one simulated
    sensor per serial when there are two or more (``simulators.rig``).
    """
    if (rig.get("turntable") or {}).get("driver") == "manual":  # hand-placed fixture
        from service.engine.placement import manual_devices  # docs/manual-fixtures.md

        # The sim twin keeps its table (a test turns it to play the operator); a real
        # chamber over Modbus gets no table driver at all: the operator is the table.
        async with open_rig({**rig, "turntable": {"driver": _NO_TABLE}}, clock, seed=seed,
                            faults=faults, sim_options=sim_options,
                            serials=serials) as devices:
            yield manual_devices(rig, devices)
        return
    driver = str((rig.get("chamber") or {}).get("driver", "sim"))
    if driver in REAL_DRIVERS:
        async with _open_modbus_rig(rig, clock, serials) as devices:
            if has_hand_axis(rig.get("turntable") or {}):  # docs/manual-fixtures.md
                devices = hand_axis_devices(rig, devices, placement_sf)
            yield devices
        return
    if driver != "sim":
        raise RigConfigError(
            f"rig {rig.get('name')!r}: unknown chamber driver {driver!r} "
            f"(expected one of {', '.join(DRIVERS)})")
    from drivers.geometry import angles_for_reference, pose_quaternion
    from simulators.rig import connect_rig, connect_sensors, start_sim_rig

    kwargs: dict[str, Any] = {"seed": seed, **(sim_options or {})}
    if faults is not None:
        kwargs["faults"] = faults
    if len(serials) > 1:
        kwargs["serials"] = list(serials)
    async with start_sim_rig(clock, **kwargs) as sim:
        chamber, turntable, accel = await _maybe_await(connect_rig(sim, clock))
        accels: dict[str, Any] = {}
        if sim.sensors:
            await accel.close()  # the first sensor's driver comes with the others
            accels = connect_sensors(sim, clock)
            accel = accels[sim.sensors[0].serial]
        n_axes = turntable.n_axes
        try:
            yield RigDevices(chamber, turntable, accel,
                             lambda ref: tuple(angles_for_reference(np.asarray(ref), n_axes)),
                             accelerometers=accels, pose_for=pose_quaternion)
        finally:
            for dev in (chamber, turntable, *(accels.values() or [accel])):
                # Modbus drivers close through their link; the serial bridge directly.
                owner = dev if hasattr(dev, "close") else getattr(dev, "link", None)
                if owner is not None and hasattr(owner, "close"):
                    await _maybe_await(owner.close())


DRIVERS = ("sim", "modbus", "espec")
#: Chamber drivers of real (or remote simulated) controllers, reached by url.
REAL_DRIVERS = ("modbus", "espec")


def has_hand_axis(turntable: dict[str, Any]) -> bool:
    """A 1-axis motorised stage whose second axis is set by hand (docs/manual-fixtures.md)."""
    return isinstance(turntable, dict) and "hand_axis" in turntable


def hand_axis_steps(turntable: dict[str, Any]) -> tuple[float, ...] | None:
    """The hand axis' indexer steps (°), ``None`` when it turns to any angle."""
    steps = (turntable.get("hand_axis") or {}).get("steps_deg")
    return None if steps is None else tuple(float(s) for s in steps)


def hand_axis_devices(rig: dict[str, Any], devices: RigDevices, sf: Any = None) -> RigDevices:
    """``devices`` with the 1-axis motor table wrapped in a
    :class:`drivers.manual_table.HandAxisTurntable` (placement requests on the service's
    board for the hand axis) and the hand-axis geometry
    (:func:`drivers.geometry.angles_for_hand_axis`): a reference the motor range and the
    hand steps cannot reach raises :class:`drivers.geometry.UnreachablePose` with why."""
    from dataclasses import replace

    from drivers.geometry import angles_for_hand_axis, pose_quaternion
    from drivers.manual_table import HandAxisTurntable
    from service.engine.placement import PlacementBoard

    if sf is None:
        from service.db.session import make_session_factory

        sf = make_session_factory()
    cfg = rig.get("turntable") or {}
    motor = devices.turntable
    table = HandAxisTurntable(motor, PlacementBoard(sf, str(rig.get("name", ""))),
                              devices.accelerometer,
                              check_samples=int(cfg.get("check_samples", 64)),
                              noise_g=float(cfg.get("noise_g", 0.2e-3)))
    steps = hand_axis_steps(cfg)
    motor_range = float(getattr(getattr(motor, "regmap", None), "range_deg", 180.0))
    # The pose is known: the motor's angle and the hand axis' (an indexer step) are the
    # 2-axis convention's (motor, hand), placed as asked or refused by the driver's check.
    return replace(devices, turntable=table,
                   angles_for=lambda ref: angles_for_hand_axis(np.asarray(ref), steps,
                                                               motor_range),
                   pose_for=pose_quaternion)
_NO_TABLE = "none"  # internal: the manual fixture's devices, opened without a table driver


def is_manual_table(turntable: dict[str, Any]) -> bool:
    """A hand-placed fixture: no table to command (docs/manual-fixtures.md)."""
    return turntable.get("driver") in ("manual", _NO_TABLE)


class RigConfigError(ValueError):
    """A rig config the drivers cannot use; the message names the key."""


def rig_config_errors(
    chamber: dict[str, Any], turntable: dict[str, Any], sensors: list[Any]
) -> list[tuple[str, str]]:
    """``(field path, problem)`` for every problem of a rig config; empty when usable."""
    from drivers.registermaps import MapError, load_chamber_map, load_turntable_map

    errors: list[tuple[str, str]] = []
    driver = chamber.get("driver") if isinstance(chamber, dict) else None
    errors += _unknown_keys("chamber", chamber,
                            ESPEC_CHAMBER_KEYS if driver == "espec" else CHAMBER_KEYS)
    errors += _unknown_keys("turntable", turntable, TURNTABLE_KEYS)
    if driver is None:
        errors.append(("chamber.driver", "missing: \"modbus\" for a controller reached by "
                                         "url, \"espec\" for an ESPEC P-300/SCP-220, "
                                         "\"sim\" for the in-process twin"))
    elif driver not in DRIVERS:
        errors.append(("chamber.driver", f"expected one of {', '.join(DRIVERS)}, got {driver!r}"))
    rng = chamber.get("range_c")
    rng_ok = isinstance(rng, list | tuple) and len(rng) == 2 and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in rng) and rng[0] < rng[1]
    if rng is not None and not rng_ok:
        errors.append(("chamber.range_c", "expected [lo, hi] in °C with lo < hi"))
    rate = chamber.get("max_rate_c_per_min")
    if rate is not None and (not isinstance(rate, int | float) or isinstance(rate, bool)
                             or not rate > 0):
        errors.append(("chamber.max_rate_c_per_min", f"expected a rate > 0 °C/min, got {rate!r}"))
    if driver not in REAL_DRIVERS:
        return errors
    if driver == "espec":
        errors += espec_config_errors(chamber)
    manual = is_manual_table(turntable)
    devices = ([("chamber", chamber)] if driver == "modbus" else []) + (
        [] if manual else [("turntable", turntable)])
    for path, cfg in devices:
        url = cfg.get("url")
        if not isinstance(url, str) or not url.startswith(("tcp://", "rtu://")):
            errors.append((f"{path}.url", "expected tcp://host:port or rtu:///dev/...?baudrate="))
        dev_id = cfg.get("device_id", 1)
        if not isinstance(dev_id, int) or not 0 <= dev_id <= 247:
            errors.append((f"{path}.device_id", "expected a Modbus unit id 0…247"))
    if (not manual and driver == "modbus" and chamber.get("url") == turntable.get("url")
            and not _per_axis_units(turntable)  # a drive per axis: _shared_bus_units
            and chamber.get("device_id", 1) == turntable.get("device_id", 1)):
        errors.append(("turntable.device_id",
                       f"the chamber answers unit {chamber.get('device_id', 1)} at the same url: "
                       "two devices on one bus need different unit ids (device_id)"))
    maps = [("chamber.map", chamber, load_chamber_map, "eurotherm3216")
            ] if driver == "modbus" else []
    if not manual:
        maps.append(("turntable.map", turntable, load_turntable_map, "soakcal-table"))
    for path, cfg, load, default in maps:
        ref = cfg.get("map", default)
        if not isinstance(ref, str):
            errors.append((path, "expected a shipped map name or a map file path"))
            continue
        try:
            regmap = load(ref)
        except MapError as exc:
            errors.append((path, str(exc)))
            continue
        errors += _limits_against_map(chamber, turntable, regmap)
        errors += _shared_bus_units(chamber, turntable, regmap)
    errors += _table_axes_errors(chamber, turntable, manual)
    scale = chamber.get("time_scale", 1.0)
    if not isinstance(scale, int | float) or isinstance(scale, bool) or not scale > 0:
        errors.append(("chamber.time_scale", "expected a number > 0 (1 for hardware)"))
    if not sensors or not isinstance(sensors[0], dict) or not isinstance(
            sensors[0].get("url"), str):
        errors.append(("sensors[0].url", "expected the sensor bridge's serial port or URL"))
        return errors
    # protocol (bridge / plain stream), framing, serial binding: one validator, the driver's
    from drivers.sensor_config import sensor_config_errors

    declared: dict[str, int] = {}
    ports: dict[str, int] = {}
    for i, entry in enumerate(sensors):
        path = f"sensors[{i}]"
        errors.extend(sensor_config_errors(entry, path))
        if not isinstance(entry, dict):
            continue
        url = entry.get("url")
        if isinstance(url, str) and url:
            # Two drivers on one port would interleave their commands and read each other's
            # replies: several sensors on one port are one multiplexing entry.
            if url in ports:
                errors.append((f"{path}.url", f"port {url} is already sensors[{ports[url]}]'s; "
                                              "several sensors on one bridge are that entry's "
                                              "'channels'"))
            ports.setdefault(url, i)
        serial = entry.get("serial")
        if serial is not None and (not isinstance(serial, str) or not serial.strip()):
            errors.append((f"{path}.serial", "expected the serial of the sensor on this port"))
            continue
        channel_of = _channel_serials(entry)
        for name in entry_serials(entry):
            if name in declared and declared[name] != i:
                key = f"channels.{channel_of[name]}" if name in channel_of else "serial"
                errors.append((f"{path}.{key}", f"sensor {name!r} is already declared by "
                                                f"sensors[{declared[name]}]"))
            declared.setdefault(name, i)
    return errors


#: Keys a rig's chamber / turntable block may use (docs: service/engine/rigs.py's docstring,
#: docs/manual-fixtures.md); anything else is a typo that would silently change the rig.
CHAMBER_KEYS = ("driver", "url", "map", "device_id", "range_c", "time_scale",
                "max_rate_c_per_min")
TURNTABLE_KEYS = ("driver", "url", "map", "device_id", "axes", "check_samples", "noise_g",
                  "unit_ids", "hand_axis")
HAND_AXIS_KEYS = ("steps_deg",)


def _table_axes_errors(chamber: dict[str, Any], turntable: dict[str, Any],
                       manual: bool) -> list[tuple[str, str]]:
    """Axes, unit ids per axis and the hand axis of a motorised table."""
    if manual:
        return []
    out: list[tuple[str, str]] = []
    axes = turntable.get("axes")  # None: the map's count (checked against the map below)
    hand = turntable.get("hand_axis")
    if axes is not None and (axes not in (1, 2, 3) or isinstance(axes, bool)):
        out.append(("turntable.axes", "expected 1, 2 or 3"))
    elif axes == 1 and hand is None:
        out.append(("turntable.axes", "one motorised axis puts gravity only in one plane of "
                                      "the sensor: add turntable.hand_axis (the second axis "
                                      "set by hand, docs/manual-fixtures.md), or use 2 or 3"))
    if hand is not None:
        out += _unknown_keys("turntable.hand_axis", hand, HAND_AXIS_KEYS)
        if axes != 1:
            out.append(("turntable.hand_axis", f"a hand axis completes a 1-axis stage: set "
                                               f"turntable.axes = 1 (got {axes!r})"))
        if chamber.get("driver") not in REAL_DRIVERS:
            out.append(("turntable.hand_axis", "the motorised axis is reached by url: "
                                               "a real chamber driver (modbus, espec)"))
        steps = hand.get("steps_deg") if isinstance(hand, dict) else None
        if steps is not None and not (
                isinstance(steps, list) and steps and all(
                    isinstance(v, int | float) and not isinstance(v, bool) for v in steps)):
            out.append(("turntable.hand_axis.steps_deg",
                        "expected the indexer's angles in °, e.g. [0, 90, 180, 270]"))
    uids = turntable.get("unit_ids")
    if uids is not None:
        n = axes if isinstance(axes, int) else len(uids) if isinstance(uids, list) else 0
        if not (isinstance(uids, list) and len(uids) == n and all(
                isinstance(u, int) and not isinstance(u, bool) and 1 <= u <= 247 for u in uids)
                and len(set(uids)) == len(uids)):
            out.append(("turntable.unit_ids", f"expected {n} distinct Modbus unit ids 1…247, "
                                              "one per axis, outer first"))
    return out


#: An ESPEC chamber's block (drivers/espec_chamber.py, docs/chambers.md): no map, so the
#: range is the rig's to give, and the safe state too.
ESPEC_CHAMBER_KEYS = ("driver", "url", "address", "baudrate", "range_c", "time_scale",
                      "max_rate_c_per_min", "safe_setpoint_c", "safe_stop")


def espec_config_errors(chamber: dict[str, Any]) -> list[tuple[str, str]]:
    """The ``espec`` chamber keys' own problems (range_c's shape is checked by the caller)."""
    out: list[tuple[str, str]] = []
    url = chamber.get("url")
    if not isinstance(url, str) or not url.strip() or url.startswith("rtu://"):
        out.append(("chamber.url", "expected the controller's serial port (/dev/ttyUSB0), "
                                   "socket://host:port or tcp://host:port"))
    if chamber.get("range_c") is None:
        out.append(("chamber.range_c", "required for an ESPEC chamber (no map gives it): "
                                       "[lo, hi] in °C the chamber may be set to"))
    addr = chamber.get("address")
    if addr is not None and (not isinstance(addr, int) or isinstance(addr, bool)
                             or not 1 <= addr <= 16):
        out.append(("chamber.address", f"expected the RS-485 address 1…16, got {addr!r} "
                                       "(omit it on RS-232 or LAN)"))
    baud = chamber.get("baudrate")
    if baud is not None and baud not in (4800, 9600, 19200):
        out.append(("chamber.baudrate", f"expected 4800, 9600 or 19200, got {baud!r}"))
    safe = chamber.get("safe_setpoint_c")
    rng = chamber.get("range_c")
    if safe is not None:
        if not isinstance(safe, int | float) or isinstance(safe, bool):
            out.append(("chamber.safe_setpoint_c", f"expected a temperature in °C, got {safe!r}"))
        elif (isinstance(rng, list | tuple) and len(rng) == 2
              and all(isinstance(v, int | float) for v in rng) and not rng[0] <= safe <= rng[1]):
            out.append(("chamber.safe_setpoint_c", f"{safe:g} °C is outside range_c "
                                                   f"[{rng[0]:g}, {rng[1]:g}]"))
    stop = chamber.get("safe_stop")
    if stop is not None and not isinstance(stop, bool):
        out.append(("chamber.safe_stop", f"expected true or false, got {stop!r}"))
    return out


def _chamber_driver(cfg: dict[str, Any], clock: Clock) -> Any:
    """The chamber driver a validated real rig's ``chamber`` block names."""
    if cfg.get("driver") == "espec":
        from drivers.espec_chamber import DEFAULT_BAUDRATE, EspecChamber, EspecSettings

        lo, hi = cfg["range_c"]
        return EspecChamber(EspecSettings(
            url=cfg["url"], range_c=(float(lo), float(hi)), address=cfg.get("address"),
            baudrate=int(cfg.get("baudrate", DEFAULT_BAUDRATE)),
            safe_setpoint_c=float(cfg.get("safe_setpoint_c", 23.0)),
            safe_stop=bool(cfg.get("safe_stop", False)),
            max_rate_c_per_min=cfg.get("max_rate_c_per_min")), clock)
    from drivers.chamber import ModbusChamber
    from drivers.modbus_link import ModbusLink
    from drivers.registermaps import load_chamber_map

    chamber_map = load_chamber_map(cfg.get("map", "eurotherm3216"))
    # The rig's device_id wins; else the map's [defaults] unit_id (1 unless it says).
    return ModbusChamber(
        ModbusLink(cfg["url"], clock, device="chamber",
                   device_id=int(cfg.get("device_id", chamber_map.unit_id))),
        chamber_map, max_rate_c_per_min=cfg.get("max_rate_c_per_min"),
    )


def _unknown_keys(block: str, cfg: Any, allowed: tuple[str, ...]) -> list[tuple[str, str]]:
    import difflib

    if not isinstance(cfg, dict):
        return [(block, "expected an object")]
    out = []
    for key in (k for k in cfg if k not in allowed):
        near = difflib.get_close_matches(str(key), allowed, n=1)
        hint = f"did you mean {near[0]!r}? " if near else ""
        out.append((f"{block}.{key}", f"unknown key ({hint}expected one of "
                                      f"{', '.join(allowed)})"))
    return out


def _limits_against_map(chamber: dict[str, Any], turntable: dict[str, Any],
                        regmap: Any) -> list[tuple[str, str]]:
    """The rig's limits must lie inside what its map (the controller) allows."""
    from drivers.registermaps import ChamberMap

    out: list[tuple[str, str]] = []
    if isinstance(regmap, ChamberMap):
        rng = chamber.get("range_c")
        lo, hi = regmap.range_c
        if (isinstance(rng, list | tuple) and len(rng) == 2
                and all(isinstance(v, int | float) for v in rng)
                and (rng[0] < lo or rng[1] > hi)):
            out.append(("chamber.range_c", f"[{rng[0]:g}, {rng[1]:g}] °C exceeds the map "
                                           f"{regmap.name}'s limits.range_c [{lo:g}, {hi:g}]"))
        rate, limit = chamber.get("max_rate_c_per_min"), regmap.max_ramp_c_per_min
        if isinstance(rate, int | float) and limit is not None and rate > limit:
            out.append(("chamber.max_rate_c_per_min", f"{rate:g} °C/min exceeds the map "
                                                      f"{regmap.name}'s {limit:g} °C/min"))
        return out
    axes = turntable.get("axes", regmap.n_axes)
    if isinstance(axes, int) and axes > regmap.n_axes:
        out.append(("turntable.axes", f"{axes} axes, but the map {regmap.name} describes "
                                      f"{regmap.n_axes}"))
    if turntable.get("unit_ids") is not None and not regmap.unit_ids:
        out.append(("turntable.unit_ids", f"the map {regmap.name} puts every axis on one unit "
                                          "id (no [axes] unit_ids): use device_id"))
    return out


def _per_axis_units(turntable: dict[str, Any]) -> bool:
    """The table is a drive per axis (its own ``unit_ids`` or its map's)."""
    from drivers.registermaps import MapError, load_turntable_map

    if turntable.get("unit_ids"):
        return True
    try:
        return bool(load_turntable_map(str(turntable.get("map", "soakcal-table"))).unit_ids)
    except (MapError, TypeError):
        return False  # the map's own error is reported where the map is checked


def _shared_bus_units(chamber: dict[str, Any], turntable: dict[str, Any],
                      regmap: Any) -> list[tuple[str, str]]:
    """A drive per axis on the chamber's bus: no drive may answer the chamber's unit id."""
    units = turntable.get("unit_ids") or getattr(regmap, "unit_ids", ())
    ours = chamber.get("device_id", 1)
    if not units or chamber.get("url") != turntable.get("url") or ours not in units:
        return []
    key = "turntable.unit_ids" if turntable.get("unit_ids") else "turntable.map"
    return [(key, f"the chamber answers unit {ours} at the same url, and so would the drive "
                  f"of axis {list(units).index(ours)} (unit ids {list(units)}): give the "
                  "drives other ids (turntable.unit_ids)")]


def entry_serials(entry: dict[str, Any]) -> list[str]:
    """The serials one sensor entry declares mounted: ``serial``, its ``channels``' serials
    and its ``serials`` table's values (the one definition: the door's 422 uses it too)."""
    out = [entry["serial"].strip()] if isinstance(entry.get("serial"), str) else []
    for table in (entry.get("channels"), entry.get("serials")):
        if isinstance(table, dict):
            out += [str(v).strip() for v in table.values() if str(v).strip() not in out]
    return out


def _channel_serials(entry: dict[str, Any]) -> dict[str, int]:
    """serial → channel of a multiplexing entry (``{}`` for a one-sensor entry)."""
    channels = entry.get("channels")
    if not isinstance(channels, dict):
        return {}
    return {str(v).strip(): int(k) for k, v in channels.items()
            if isinstance(k, str) and k.isdigit()}


def sensor_entries(rig: dict[str, Any], serials: Sequence[str]
                   ) -> dict[str, tuple[int, int | None]]:
    """``(entry index, channel)`` of the sensor entry mounting each serial; the channel is
    ``None`` on a one-sensor bridge.

    :class:`RigConfigError` naming a serial no entry declares, or two serials behind one
    entry that has no ``channels`` (one bridge per sensor, unless it multiplexes).
    """
    entries = rig.get("sensors") or []
    where: dict[str, int] = {}
    for i, entry in enumerate(entries):
        if isinstance(entry, dict):
            for name in entry_serials(entry):
                where.setdefault(name, i)
    out: dict[str, tuple[int, int | None]] = {}
    for serial in serials:
        key = str(serial).strip()
        if key not in where:
            raise RigConfigError(
                f"rig {rig.get('name')!r}: sensor {key!r} is not mounted (declared: "
                f"{', '.join(sorted(where)) or 'none'})")
        i = where[key]
        out[str(serial)] = (i, _channel_serials(entries[i]).get(key))
    shared = [s for s, (i, ch) in out.items()
              if ch is None and sum(j == i for j, _ in out.values()) > 1]
    if shared:
        raise RigConfigError(
            f"rig {rig.get('name')!r}: sensors {', '.join(shared)} are behind one bridge "
            f"(sensors[{out[shared[0]][0]}]) that has no 'channels'; one bridge per sensor "
            "is needed, or declare the multiplexing bridge's sensors in its 'channels'")
    return out


def rig_time_scale(rig: dict[str, Any]) -> float | None:
    """Rig time per wall second for a ``modbus`` rig; ``None`` for ``sim`` (the service's)."""
    chamber = rig.get("chamber") or {}
    if chamber.get("driver", "sim") not in REAL_DRIVERS:
        return None
    return float(chamber.get("time_scale", 1.0))


@asynccontextmanager
async def _open_modbus_rig(rig: dict[str, Any], clock: Clock,
                          serials: Sequence[str] = ()) -> AsyncIterator[RigDevices]:
    """Real drivers on the URLs of the config (see the module docstring); with two or more
    ``serials``, one driver per serial on the port of the entry that declares it."""
    from drivers.geometry import angles_for_reference, pose_quaternion
    from drivers.modbus_link import ModbusLink
    from drivers.registermaps import load_turntable_map
    from drivers.sensor_config import (
        make_accelerometer,
        make_multiplexed_bridge,
        parse_sensor_config,
    )
    from drivers.turntable import ModbusTurntable

    chamber_cfg = rig.get("chamber") or {}
    table_cfg = rig.get("turntable") or {}
    sensors = rig.get("sensors") or []
    problems = rig_config_errors(chamber_cfg, table_cfg, sensors)
    if problems:
        path, why = problems[0]
        raise RigConfigError(f"rig {rig.get('name')!r}: {path}: {why}")
    chamber = _chamber_driver(chamber_cfg, clock)
    n_axes = int(table_cfg.get("axes", 3))
    table: Any = None  # a hand-placed fixture: open_rig puts the operator's table in
    if not is_manual_table(table_cfg):
        table_map = load_turntable_map(table_cfg.get("map", "soakcal-table"))
        n_axes = int(table_cfg.get("axes", table_map.n_axes))
        if table_cfg.get("unit_ids") is not None:  # the drives' ids on this rig's bus
            from dataclasses import replace

            table_map = replace(table_map, unit_ids=tuple(int(u) for u in
                                                         table_cfg["unit_ids"]))
        table = ModbusTurntable(
            ModbusLink(table_cfg["url"], clock, device="turntable",
                       device_id=int(table_cfg.get("device_id", table_map.unit_id))),
            table_map, n_axes=n_axes,
        )
    accels: dict[str, Any] = {}
    bindings: dict[str, SerialBinding] = {}
    binding = binding_for_rig(rig)
    # One campaign serial on a multiplexing bridge: that channel, not the unaddressed form.
    one_on_channel = len(serials) == 1 and any(
        str(serials[0]).strip() in _channel_serials(e) for e in sensors if isinstance(e, dict))
    if len(serials) > 1 or one_on_channel:
        muxes: dict[int, Any] = {}  # entry index → its MultiplexedBridge: one line per port
        for serial, (i, channel) in sensor_entries(rig, serials).items():
            link = parse_sensor_config(sensors[i], f"sensors[{i}]")
            if channel is None:
                accels[serial] = make_accelerometer(link, clock)
            else:
                if i not in muxes:
                    muxes[i] = make_multiplexed_bridge(link, clock)
                accels[serial] = muxes[i].channel(channel, device=f"sensor {serial}")
            bindings[serial] = SerialBinding(link.serial_binding, dict(link.serials))
        accel = accels[str(serials[0])]
        if one_on_channel:  # the one-sensor path of the runner: its binding, no dict
            binding, accels, bindings = bindings[str(serials[0])], {}, {}
    else:
        accel = make_accelerometer(parse_sensor_config(sensors[0]), clock)
    try:
        yield RigDevices(chamber, table, accel,
                         lambda ref: tuple(angles_for_reference(np.asarray(ref), n_axes)),
                         binding, accelerometers=accels, bindings=bindings,
                         pose_for=pose_quaternion)
    finally:
        await chamber.close()
        if table is not None:
            await table.link.close()
        for dev in accels.values() or [accel]:
            await dev.close()


async def _maybe_await(v: Any) -> Any:
    import inspect

    return await v if inspect.isawaitable(v) else v
