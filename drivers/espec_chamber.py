"""ESPEC chamber driver: the P-300 / SCP-220 controllers' ASCII command protocol.

ESPEC's own controllers (P-300, SCP-220 and the ones that answer the same commands)
speak a line protocol, not Modbus, so no register map can describe them; this
driver implements :class:`drivers.protocols.Chamber` on that protocol directly.

Sources (public), read to learn the protocol; nothing here is copied from them:

* ESPEC North America's ChamberConnectLibrary (MIT), ``chamberconnectlibrary/p300.py``
  (``read_temp``: ``TEMP?``; ``read_mon``: ``MON?``; ``read_mode``: ``MODE?``;
  ``read_alarm``: ``ALARM?``; ``read_type``: ``TYPE?``; ``read_rom``: ``ROM?``;
  ``write_temp``: ``TEMP, S<sp>``; ``write_mode_constant`` / ``_standby`` / ``_off``:
  ``MODE,CONSTANT`` / ``MODE,STANDBY`` / ``MODE,OFF``; ``write_power``: ``POWER,ON``;
  ``write_run_prgm``: ``RUN PRGM, TEMP<a> GOTEMP<b> TIME<h>:<m>``, the only ramp) and
  ``chamberconnectlibrary/especinteract.py`` (framing: ``\\r\\n`` both ways; RS-485 address
  as a ``<n>,`` prefix; refusals ``NA:<reason>`` with the reason table reproduced in
  :data:`REFUSALS` in our own words).
* ESPEC's "Communication Manual" for the P-300 / SCP-220 (the command chapter the library
  implements; section numbers vary by edition, so the commands above are cited by name).
  A setting command is acknowledged ``OK:<the command>`` (also in the public ATWG driver
  for the ESPEC SH-641, ``espec/sh_641_drv.py``, which parses ``OK:TEMP,S25``).

What the protocol gives, and what it does not:

* ``TEMP?`` → ``PV,SP,upper limit,lower limit`` (°C, one decimal): the process value,
  the setpoint, and the controller's own temperature limits (its absolute alarm
  limits, ``TEMP, H``/``TEMP, L``).
* ``MON?`` → ``temperature,humidity,mode,alarm count``; humidity is empty on a
  temperature-only chamber. Mode ``OFF``, ``STANDBY``, ``CONSTANT`` or ``RUN`` (a program).
* ``ALARM?`` → ``count,code,code...``: the active alarm codes (numbers; their names are
  in the chamber's own manual, so they are reported as ``alarm <code>``).
* No working setpoint (``working_setpoint_c`` is ``None``: arrival is judged on the PV)
  and no static ramp: in constant mode the chamber steps to the setpoint at its own
  rate. A ramp exists only as a program step (``RUN PRGM``), which this driver does not
  run: a program owns the setpoint and ends in a mode of its own. A commanded ramp is
  honoured by the rule every chamber without a ramp follows (:mod:`drivers.ramp_rule`):
  0 (step) is accepted, and so is a rate at or above the rig's ``max_rate_c_per_min``
  (the chamber's own fastest rate: stepping the setpoint then moves the air no faster
  than asked); a slower one is refused naming the fix (``ramp_c_per_min = 0``).

Transport: anything pyserial's ``serial_for_url`` opens (``/dev/ttyUSB0`` at the
controller's baud rate, ``socket://host:port`` for a serial-to-Ethernet adapter or the
controller's LAN port); ``tcp://host:port`` is accepted as ``socket://``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import serial

from drivers.chamber_park import park_chamber
from drivers.clock import Clock
from drivers.faults import (
    ConfigurationFault,
    ConnectionLost,
    DeviceFault,
    DeviceTimeout,
    ExceptionReply,
    ProtocolError,
    ValueOutOfRange,
)
from drivers.protocols import ChamberStatus
from drivers.ramp_rule import RampControl, ramp_refusal
from drivers.sensor_bridge import SerialLine

LINE_END = b"\r\n"
DEFAULT_BAUDRATE = 9600  # the controller's factory setting per ESPEC's library default
REPLY_TIMEOUT_S = 3.0  # ESPEC's library waits 3 s for a reply
SETPOINT_RESOLUTION_C = 0.1  # ``TEMP, S%.1f``: the protocol carries one decimal

#: ``NA:<reason>`` replies (ESPEC's especinteract.py lists them) and what each means here.
#: Refusals of the request itself are permanent (:class:`ConfigurationFault`); a controller
#: momentarily not ready is retryable.
REFUSALS: dict[str, str] = {
    "CMD ERR": "the controller does not know this command",
    "ADDR ERR": "wrong RS-485 address",
    "CONT NOT READY-1": "the chamber has no such function (humidity, product control)",
    "CONT NOT READY-2": "no program is running",
    "CONT NOT READY-3": "this controller does not support the command",
    "CONT NOT READY-4": "keys cannot be locked while the controller is off",
    "PARA ERR": "a parameter is missing or not understood",
    "DATA OUT OF RANGE": "the value is outside the controller's range",
    "PROTECT ON": "the controller's data protection (key protect) is on",
    "INVALID REQ": "the function is not supported",
    "CHB NOT READY": "the controller could not act on the command now",
}
_RETRYABLE = ("CHB NOT READY",)

MODES = ("OFF", "STANDBY", "CONSTANT", "RUN")
#: Modes in which the controller controls the chamber's temperature.
CONTROLLING = ("CONSTANT", "RUN")


@dataclass(frozen=True)
class EspecSettings:
    """A rig config's ``chamber`` block for ``driver = "espec"`` (docs/chambers.md)."""

    url: str
    range_c: tuple[float, float]
    address: int | None = None  # RS-485 address; None on RS-232 / LAN
    baudrate: int = DEFAULT_BAUDRATE
    safe_setpoint_c: float = 23.0  # where a campaign's end leaves the chamber
    safe_stop: bool = False  # the park also puts the controller in STANDBY
    # The chamber's own fastest rate, °C/min (its data sheet): the rate it steps at.
    max_rate_c_per_min: float | None = None


def espec_ramp_control(max_rate_c_per_min: float | None) -> RampControl:
    """What an ESPEC chamber does with a commanded ramp (:mod:`drivers.ramp_rule`): it has
    none outside a program; it steps at ``max_rate_c_per_min`` (the rig's; None: unstated)."""
    return RampControl("an ESPEC P-300/SCP-220", False, "it ramps only inside a program, "
                       "which this driver does not run", max_rate_c_per_min)


def port_url(url: str) -> str:
    """The pyserial URL of a rig config's ``url`` (``tcp://`` means a raw TCP socket)."""
    return "socket://" + url[len("tcp://"):] if url.startswith("tcp://") else url


@dataclass(frozen=True)
class TempReading:
    """``TEMP?``: process value, setpoint and the controller's own limits, °C."""

    process_c: float
    setpoint_c: float
    upper_limit_c: float
    lower_limit_c: float


@dataclass(frozen=True)
class Monitor:
    """``MON?``: temperature, humidity (None: no humidity), mode and active alarm count."""

    process_c: float
    humidity_pct: float | None
    mode: str
    n_alarms: int


class EspecChamber:
    """:class:`drivers.protocols.Chamber` over ESPEC's ASCII protocol (module docstring)."""

    def __init__(self, settings: EspecSettings, clock: Clock, *, device: str = "chamber",
                 timeout_s: float = REPLY_TIMEOUT_S) -> None:
        self.settings = settings
        self.device = device
        self.url = settings.url
        self._line = SerialLine(port_url(settings.url), clock, baudrate=settings.baudrate,
                                timeout_s=timeout_s, attempts=1, device=device,
                                name="espec-chamber")

    # --- Chamber protocol --------------------------------------------------------------
    @property
    def range_c(self) -> tuple[float, float]:
        return self.settings.range_c

    @property
    def safe_setpoint_c(self) -> float:
        return self.settings.safe_setpoint_c

    @property
    def stop_when_safe(self) -> bool:
        return self.settings.safe_stop

    #: The protocol has no static ramp (rig check and the engine read this).
    has_static_ramp = False

    async def read_status(self) -> ChamberStatus:
        temp = await self.read_temp()
        mon = await self.read_monitor()
        alarms = await self.read_alarms() if mon.n_alarms else ()
        return ChamberStatus(process_c=temp.process_c, setpoint_c=temp.setpoint_c,
                             working_setpoint_c=None, ramp_c_per_min=0.0,
                             running=mon.mode in CONTROLLING, alarms=alarms)

    async def set_setpoint(self, setpoint_c: float) -> None:
        lo, hi = self.range_c
        if not lo <= setpoint_c <= hi:
            raise ValueOutOfRange(self.device, f"setpoint {setpoint_c} °C outside {lo}…{hi} °C")
        await self.command(f"TEMP, S{setpoint_c:.1f}")

    @property
    def ramp_control(self) -> RampControl:
        """No static ramp; the chamber's own rate is the rig's ``max_rate_c_per_min``."""
        return espec_ramp_control(self.settings.max_rate_c_per_min)

    async def set_ramp_rate(self, ramp_c_per_min: float) -> None:
        """Nothing to write: constant mode steps at the chamber's own rate. A commanded
        rate is honoured when it is 0 (step) or at or above that rate (one rule for every
        chamber: :mod:`drivers.ramp_rule`); else refused naming the fix."""
        if ramp_c_per_min < 0:
            raise ValueOutOfRange(self.device, f"ramp rate {ramp_c_per_min} °C/min < 0")
        refused = ramp_refusal(self.ramp_control, ramp_c_per_min)
        if refused is not None:
            raise ValueOutOfRange(self.device, refused)

    async def run(self) -> None:
        """Constant mode (control at the setpoint written with ``TEMP, S``).

        A program running on the controller owns its setpoint: it is not ended here
        (someone started it), the campaign is refused with the fix instead.
        """
        mode = await self.read_mode()
        if mode == "CONSTANT":
            return
        if mode == "RUN":
            raise ConfigurationFault(
                self.device, "a program is running on the controller (MODE? = RUN) and owns "
                "the setpoint: end the program at the controller (or set it to constant "
                "mode) before the campaign")
        # From OFF the controller is powered up into constant mode (ESPEC's write_power).
        await self.command("POWER,ON" if mode == "OFF" else "MODE,CONSTANT")

    async def stop(self) -> None:
        """Standby: the controller stops controlling (the panel stays on)."""
        await self.command("MODE,STANDBY")

    async def park(self, setpoint_c: float | None = None) -> str:
        """The safe state (:meth:`drivers.protocols.Chamber.park`): the setpoint to
        ``setpoint_c`` or the rig's ``safe_setpoint_c`` (clamped to the range, and said),
        then standby where the rig says ``safe_stop``."""
        return await park_chamber(self, setpoint_c, stopped="controller in standby")

    #: What to check when the controller does not answer (rig check's connect fix).
    connect_fix = ("check the URL or serial port, the cabling, the baud rate and the RS-485 "
                   "address (chamber.address) set at the ESPEC controller's communication "
                   "settings")

    async def rig_checks(self, range_c: tuple[float, float]
                         ) -> list[tuple[str, str, str, str]]:
        """``(check, status, detail, fix)`` of what the controller itself can tell a rig
        check: that it is an ESPEC controller (``TYPE?``), that ``range_c`` lies inside
        its maximum and its own temperature limits (``TEMP?`` fields 3 and 4, where a
        setpoint beyond is refused ``DATA OUT OF RANGE``), and that no program owns the
        setpoint (``MODE?``)."""
        kind, max_c = await self.read_type()
        out = [("connect", "pass", f"answers at {self.url}", ""),
               ("identity", "pass", f"TYPE? says controller {kind}, maximum {max_c:g} °C", "")]
        lo, hi = range_c
        temp = await self.read_temp()
        if hi > max_c:
            out.append(("limits", "fail", f"range_c upper end {hi:g} °C exceeds the chamber's "
                        f"maximum {max_c:g} °C (TYPE?)",
                        f"set chamber.range_c's upper end to at most {max_c:g}"))
        elif lo < temp.lower_limit_c or hi > temp.upper_limit_c:
            out.append(("limits", "fail", f"range_c [{lo:g}, {hi:g}] °C is outside the "
                        f"controller's limits [{temp.lower_limit_c:g}, {temp.upper_limit_c:g}] "
                        "°C (TEMP?): a setpoint beyond them is refused",
                        f"narrow chamber.range_c to [{max(lo, temp.lower_limit_c):g}, "
                        f"{min(hi, temp.upper_limit_c):g}], or widen the controller's "
                        "temperature limits at its panel"))
        else:
            out.append(("limits", "pass", f"range_c [{lo:g}, {hi:g}] °C inside the "
                        f"controller's limits [{temp.lower_limit_c:g}, "
                        f"{temp.upper_limit_c:g}] °C", ""))
        mode = await self.read_mode()
        if mode == "RUN":
            out.append(("mode", "fail", "a program is running (MODE? = RUN): it owns the "
                        "setpoint, so a setpoint written here would not be followed",
                        "end the program at the controller, or set it to constant mode"))
        elif mode == "CONSTANT":
            out.append(("mode", "pass", "constant mode: controls at the setpoint written", ""))
        else:
            out.append(("mode", "pass", f"{mode.lower()}: a campaign puts it in constant "
                        "mode", ""))
        return out

    async def close(self) -> None:
        """Release the port (the controller keeps its last command)."""
        await self._line.close()

    # --- protocol reads ----------------------------------------------------------------
    async def read_temp(self) -> TempReading:
        f = await self._fields("TEMP?", 4)
        return TempReading(*(self._number("TEMP?", x) for x in f[:4]))

    async def read_monitor(self) -> Monitor:
        f = await self._fields("MON?", 4)
        mode = f[2].strip()
        if mode not in MODES:
            raise ProtocolError(self.device, f"MON? mode {mode!r} is none of {', '.join(MODES)}")
        humidity = self._number("MON?", f[1]) if f[1].strip() else None
        return Monitor(self._number("MON?", f[0]), humidity, mode,
                       int(self._number("MON?", f[3])))

    async def read_mode(self) -> str:
        mode = (await self.command("MODE?")).strip()
        if mode not in MODES:
            raise ProtocolError(self.device, f"MODE? reply {mode!r} is none of {', '.join(MODES)}")
        return mode

    async def read_alarms(self) -> tuple[str, ...]:
        """Active alarms as ``alarm <code>`` (the codes' names are in the chamber's manual)."""
        f = await self._fields("ALARM?", 1)
        return tuple(f"alarm {code.strip()}" for code in f[1:] if code.strip())

    async def read_type(self) -> tuple[str, float]:
        """``TYPE?``: (the controller's type field, its maximum temperature °C)."""
        f = await self._fields("TYPE?", 3)
        return f[-2].strip(), self._number("TYPE?", f[-1])

    async def command(self, text: str) -> str:
        """One command, its reply line (without ``OK:`` for a setting); ``NA:`` → a fault."""
        reply = await self._line.call(self._exchange_blocking, text)
        if reply.startswith("NA:"):
            raise self._refusal(text, reply[3:].strip())
        if not text.endswith("?") and not text.startswith("?"):
            # A setting is acknowledged with its own echo: anything else was not it.
            if not reply.startswith("OK:"):
                raise ProtocolError(self.device, f"{text!r} acknowledged with {reply[:60]!r}, "
                                                 "expected 'OK:...'")
            return reply[3:]
        return reply

    # --- internals -----------------------------------------------------------------------
    async def _fields(self, query: str, n_min: int) -> list[str]:
        f = (await self.command(query)).split(",")
        if len(f) < n_min:
            raise ProtocolError(self.device, f"{query} reply {','.join(f)[:60]!r} has "
                                             f"{len(f)} fields, expected at least {n_min}")
        return f

    def _number(self, query: str, text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise ProtocolError(self.device, f"{query} field {text!r} is not a number") from None
        if not math.isfinite(value):
            raise ProtocolError(self.device, f"{query} field {text!r} is not a reading")
        return value

    def _exchange_blocking(self, port: serial.SerialBase, text: str) -> str:
        addr = self.settings.address
        line = (f"{addr}," if addr is not None else "") + text
        try:
            port.reset_input_buffer()
            port.write(line.encode("ascii") + LINE_END)
            raw = port.read_until(LINE_END)
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(self.device, f"{self.url}: {exc}") from exc
        if not raw.endswith(LINE_END):
            raise DeviceTimeout(self.device, f"no reply to {text!r} within "
                                             f"{port.timeout:.1f} s")
        try:
            return raw[:-len(LINE_END)].decode("ascii")
        except UnicodeDecodeError:
            raise ProtocolError(self.device, f"reply to {text!r} is not ASCII: "
                                             f"{raw[:40]!r}") from None

    def _refusal(self, text: str, reason: str) -> DeviceFault:
        meaning = REFUSALS.get(reason, "reason not in ESPEC's list")
        message = f"refuses {text!r}: NA:{reason} ({meaning})"
        if reason == "PROTECT ON":
            message += "; turn key protect off at the controller"
        if reason in _RETRYABLE:
            return ExceptionReply(self.device, message)
        return ConfigurationFault(self.device, message)
