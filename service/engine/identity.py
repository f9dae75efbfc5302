"""Which sensor is connected: checked once at campaign start (docs/sensor-bridge.md, "Identity").

The engine calls :func:`verify_sensor` before the first acquisition. It reads
the bridge's ``ID`` (board uid, fixture-EEPROM serial, ADXL355 id registers),
checks that the part is an ADXL355 and that the serial bound to what is
connected is the serial the campaign names. Anything else is a
:class:`SensorMismatch` naming both serials, a non-retryable fault: a typo must
never store a calibration under the wrong part.

How a serial is bound to what is connected (``serial_binding`` in the rig's
sensor config, :mod:`drivers.sensor_config`):

* ``eeprom``: the fixture carries an EEPROM holding the sensor's serial
  (written once with the bridge's ``SN`` command when the sensor is glued to
  the fixture); the bridge reports it in ``ID``.
* ``table``: the rig config maps each bridge board's unique id to the serial of
  the sensor wired to it (``serials``), for fixtures without an EEPROM. A sensor on
  a multiplexing bridge's channel is looked up as ``"<board uid>@<channel>"``.
* ``auto`` (default): the EEPROM serial when the bridge reports one, else the table.
* ``any``: the operator's word. The ``sim`` rig uses it (its twin mounts the
  sensor the campaign names) and so must plain streams, which report no ids.
  The ids are still recorded; ``bound_by`` says the serial was not checked.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from drivers import adxl355
from drivers.faults import ConfigurationFault
from drivers.protocols import Accelerometer, SensorIdentity
from drivers.sensor_config import BINDING_MODES, BindingMode, parse_sensor_config

#: ADXL355 id registers 0x00-0x02 (data sheet register map).
ADXL355_IDS = {"devid_ad": adxl355.DEVID_AD, "devid_mst": adxl355.DEVID_MST,
               "partid": adxl355.PARTID}


class SensorMismatch(ConfigurationFault):
    """The connected sensor is not the one the campaign names (or not an ADXL355 at all)."""

    def __init__(self, device: str, message: str) -> None:
        super().__init__(device, message, None)


@dataclass(frozen=True)
class SerialBinding:
    """How the campaign's serial is checked against what is connected (module docstring)."""

    mode: BindingMode = "auto"
    table: Mapping[str, str] = field(default_factory=dict)  # board uid → serial

    def __post_init__(self) -> None:
        if self.mode not in BINDING_MODES:
            raise ValueError(f"serial binding must be one of {', '.join(BINDING_MODES)}, "
                             f"got {self.mode!r}")


@dataclass(frozen=True)
class VerifiedSensor:
    """The outcome of the start-of-campaign check: what to store with the recording."""

    serial: str  # the campaign's serial, as confirmed
    bound_by: str  # "eeprom", "table" or "any" (not checked: operator's word / sim twin)
    identity: SensorIdentity

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: recording header / calibration metadata (``sensor_identity``)."""
        return {"serial": self.serial, "bound_by": self.bound_by,
                **{f"reported_{k}": v for k, v in self.identity.as_dict().items()}}


def binding_for_rig(rig: Mapping[str, Any]) -> SerialBinding:
    """The binding a stored rig config means: ``any`` for the ``sim`` twin, else its sensor's."""
    if str((rig.get("chamber") or {}).get("driver", "sim")) == "sim":
        return SerialBinding("any")
    sensors = rig.get("sensors") or [{}]
    link = parse_sensor_config(sensors[0])
    return SerialBinding(link.serial_binding, dict(link.serials))


async def verify_sensor(accel: Accelerometer, expected_serial: str, binding: SerialBinding,
                        *, device: str = "sensor") -> VerifiedSensor:
    """Ask the sensor who it is and check it against the campaign (see :func:`check_identity`)."""
    return check_identity(await accel.identify(), expected_serial, binding, device=device)


def check_identity(identity: SensorIdentity, expected_serial: str, binding: SerialBinding,
                   *, device: str = "sensor") -> VerifiedSensor:
    """Pure check; :class:`SensorMismatch` naming both serials (or both ids) on any mismatch."""
    expected = expected_serial.strip()
    if not expected:
        raise SensorMismatch(device, "the campaign names no sensor serial")
    _check_part_ids(identity, device)
    if binding.mode == "any":
        return VerifiedSensor(expected, "any", identity)
    uid = identity.board_uid.strip()
    # One board, several sensors: each channel is its own row of the table.
    key = uid if identity.channel is None or not uid else f"{uid}@{identity.channel}"
    eeprom_serial = identity.serial.strip()
    mode = binding.mode
    if mode == "auto":
        mode = "eeprom" if eeprom_serial else "table"
    if mode == "eeprom":
        if not eeprom_serial:
            raise SensorMismatch(device, f"campaign names {expected} but bridge "
                                         f"{key or '(no uid)'} reports no serial (fixture "
                                         f"EEPROM blank or absent): program it with the "
                                         f"bridge's SN command or bind it in 'serials'")
        connected, where = eeprom_serial, f"fixture EEPROM on bridge {key or '(no uid)'}"
    else:
        if not uid:
            raise SensorMismatch(device, f"campaign names {expected} but the bridge reports "
                                         f"no board uid to look up in 'serials' "
                                         f"(a v1 bridge? bind by its serial: 'eeprom')")
        if key not in binding.table:
            raise SensorMismatch(device, f"campaign names {expected} but bridge {key} is not "
                                         f"in the rig's 'serials' table "
                                         f"({', '.join(sorted(binding.table)) or 'empty'})")
        connected, where = binding.table[key].strip(), f"rig table entry for bridge {key}"
    # Case and surrounding blanks are not part of a serial: a scanned "sn-0001" is SN-0001.
    if connected.casefold() != expected.casefold():
        raise SensorMismatch(device, f"campaign names sensor {expected} but {connected} is "
                                     f"connected ({where})")
    return VerifiedSensor(expected, mode, identity)


def _check_part_ids(identity: SensorIdentity, device: str) -> None:
    read = {k: getattr(identity, k) for k in ADXL355_IDS}
    if all(v is None for v in read.values()):
        return  # v1 bridge or plain stream: nothing reported, nothing to check
    if any(v is None for v in read.values()) or read != ADXL355_IDS:
        got = " ".join("--" if v is None else f"{v:02X}" for v in read.values())
        hint = " (no sensor answering on SPI: check wiring)" if got in ("00 00 00",
                                                                        "FF FF FF") else ""
        raise SensorMismatch(device, f"bridge {identity.board_uid or '(no uid)'} reads part "
                                     f"ids {got} (DEVID_AD DEVID_MST PARTID) where an ADXL355 "
                                     f"reads AD 1D ED{hint}")
