"""Small async device protocols the campaign engine drives.

Real drivers (Modbus chamber and turntable, serial sensor bridge) and the
in-process simulators implement these; the engine sees nothing else. Units are
in every name. Faults are raised as :mod:`drivers.faults` exceptions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@dataclass(frozen=True)
class ChamberStatus:
    """One read of the chamber controller."""

    process_c: float  # air temperature (PV), °C
    setpoint_c: float  # target setpoint (SP), °C
    # Ramping setpoint the controller is tracking now (WSP), °C; None: the controller has no
    # such register (its map lists it under absent_roles), arrival is then judged on the PV.
    working_setpoint_c: float | None
    ramp_c_per_min: float  # ramp-rate limit, °C/min (0 = step)
    running: bool
    alarms: tuple[str, ...] = ()


@runtime_checkable
class Chamber(Protocol):
    async def read_status(self) -> ChamberStatus: ...

    async def set_setpoint(self, setpoint_c: float) -> None: ...

    async def set_ramp_rate(self, ramp_c_per_min: float) -> None: ...

    async def run(self) -> None: ...

    async def stop(self) -> None: ...

    @property
    def range_c(self) -> tuple[float, float]:
        """Allowed setpoint range of this chamber, °C."""
        ...

    async def park(self, setpoint_c: float | None = None) -> str:
        """Leave the chamber in its own safe state (its teardown at a campaign's end).

        The setpoint goes to ``setpoint_c`` when given (a campaign's override), else to
        the device's own safe setpoint (a register map's ``[safe] setpoint_c``); where the
        device says so (``[safe] stop``) the controller is then stopped. Returns what was
        done, in words, for the park report a person reads.
        """
        ...


@dataclass(frozen=True)
class TurntableStatus:
    angles_deg: tuple[float, ...]  # one per axis (outer first)
    in_position: bool
    moving: bool
    faults: tuple[str, ...] = ()
    # Every axis homed (the map's "homed" status bit); None: the table reports no homing.
    homed: bool | None = None


@runtime_checkable
class Turntable(Protocol):
    @property
    def n_axes(self) -> int: ...

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        """Command all axes; returns once the command is accepted (not when arrived)."""
        ...

    async def read_status(self) -> TurntableStatus: ...

    async def stop(self) -> None: ...

    async def park(self) -> str:
        """Leave the table in its own safe state: stopped, then sent to its rest angles (a
        register map's ``[safe] angles_deg``, else home); returns once the move is
        accepted, not when arrived. A table with nothing to move says so. Returns what
        was done, in words, for the park report a person reads.
        """
        ...


@dataclass(frozen=True)
class SensorIdentity:
    """What the sensor side says it is (docs/sensor-bridge.md, "Identity").

    ``serial`` is the serial the bridge reports (from the fixture EEPROM; ""
    when it holds none). The remaining fields default to "unknown" so v1
    bridges, streaming sensors and fakes that report only the first three
    still fit.
    """

    model: str  # e.g. "ADXL355"
    serial: str
    firmware: str
    board_uid: str = ""  # the bridge board's / fixture's unique id, "" when not reported
    devid_ad: int | None = None  # ADXL355 register 0x00, 0xAD (Analog Devices)
    devid_mst: int | None = None  # register 0x01, 0x1D (Analog Devices MEMS)
    partid: int | None = None  # register 0x02, 0xED for the ADXL355
    revid: int | None = None  # register 0x03, silicon revision
    protocol: str = ""  # link that reported it: "v2", "v1", "stream", ... ("" unknown)
    channel: int | None = None  # the sensor's channel on a multiplexing bridge; None: one sensor

    def as_dict(self) -> dict[str, str | int | None]:
        """JSON-ready form for the recording and calibration metadata; ids as ``0xNN``."""

        def hex_id(v: int | None) -> str | None:
            return None if v is None else f"0x{v:02X}"

        return {
            "model": self.model, "serial": self.serial, "firmware": self.firmware,
            "board_uid": self.board_uid or None,
            "devid_ad": hex_id(self.devid_ad), "devid_mst": hex_id(self.devid_mst),
            "partid": hex_id(self.partid), "revid": hex_id(self.revid),
            "protocol": self.protocol or None, "channel": self.channel,
        }


@dataclass(frozen=True)
class Acquisition:
    """N raw samples averaged into one recording row (recording format v1 columns)."""

    mean_g: tuple[float, float, float]
    sd_g: tuple[float, float, float]
    n: int
    sensor_c: float  # mean of the sensor's own temperature channel, °C
    sensor_c_span: float  # max - min of the temperature channel during the capture, °C
    saturated: bool  # any raw sample at the range limit
    duration_s: float


@runtime_checkable
class Accelerometer(Protocol):
    async def identify(self) -> SensorIdentity: ...

    async def configure(self, range_g: float, odr_hz: float) -> None: ...

    async def acquire(self, n_samples: int) -> Acquisition: ...
