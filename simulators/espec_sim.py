"""An ESPEC P-300 / SCP-220 twin: the controller's ASCII protocol in front of the chamber
physics of :mod:`simulators.chamber_sim`.

Speaks the commands :mod:`drivers.espec_chamber` uses (``TEMP?``, ``MON?``, ``MODE?``,
``ALARM?``, ``TYPE?``, ``ROM?``, ``TEMP, S<sp>``, ``MODE,CONSTANT|STANDBY|OFF``,
``POWER,ON|OFF``), framed by ``\\r\\n``, optionally behind an RS-485 ``<address>,`` prefix;
anything else is ``NA:CMD ERR``. The controller is configured by :class:`EspecSetup` like
the bench one (its mode, its limits, alarms, key protect, a running program), so a driver
or a rig check that trusts a wrong assumption meets it here as it would on the bench.
"""

from __future__ import annotations

import asyncio
import re
from dataclasses import dataclass

import numpy as np

from simulators.chamber_sim import ChamberPhysics
from simulators.line_server import LineServer, start_line_server


@dataclass
class EspecSetup:
    """How the simulated controller is set up (mutate while it runs).

    * ``mode``: ``OFF``, ``STANDBY``, ``CONSTANT`` or ``RUN`` (a program runs: it owns the
      setpoint; ``TEMP, S`` is stored as the constant setpoint, not followed).
    * ``upper_limit_c`` / ``lower_limit_c``: the controller's temperature limits
      (``TEMP?`` fields 3 and 4); a setpoint outside is ``NA:DATA OUT OF RANGE``.
    * ``alarms``: active alarm codes (``ALARM?``, ``MON?``'s count).
    * ``key_protect``: settings are refused ``NA:PROTECT ON``.
    * ``address``: the RS-485 address; ``None`` answers unaddressed commands only; a
      command for another address gets no reply.
    * ``humidity``: a temperature-and-humidity chamber (``MON?`` carries a humidity).
    """

    mode: str = "CONSTANT"
    upper_limit_c: float = 180.0
    lower_limit_c: float = -70.0
    alarms: tuple[int, ...] = ()
    key_protect: bool = False
    address: int | None = None
    humidity: bool = False
    max_temp_c: float = 180.0


class EspecController:
    """The protocol state machine over one :class:`ChamberPhysics` (no I/O)."""

    def __init__(self, physics: ChamberPhysics, setup: EspecSetup | None = None) -> None:
        self.physics = physics
        self.setup = setup or EspecSetup()
        self.constant_sp_c = physics.setpoint_c  # the constant-mode setpoint (TEMP, S)
        self._apply_mode()

    def answer(self, line: str) -> str | None:
        """The reply line to one command line (without ``\\r\\n``); ``None``: no reply."""
        self.physics.advance_to()
        text = line.strip()
        if self.setup.address is not None:
            m = re.fullmatch(r"(\d+),(.*)", text)
            if m is None or int(m.group(1)) != self.setup.address:
                return None  # not for this controller: silence, as on a shared RS-485 bus
            text = m.group(2).strip()
        try:
            return self._dispatch(text)
        except _Refused as refused:
            return f"NA:{refused.reason}"

    # --- commands ----------------------------------------------------------------------
    def _dispatch(self, text: str) -> str:
        p, s = self.physics, self.setup
        if text == "TEMP?":
            return f"{p.process_value_c():.1f},{p.setpoint_c:.1f},{s.upper_limit_c:.1f}," \
                   f"{s.lower_limit_c:.1f}"
        if text == "MON?":
            humidity = "45" if s.humidity else ""
            return f"{p.process_value_c():.1f},{humidity},{s.mode},{len(s.alarms)}"
        if text == "MODE?":
            return s.mode
        if text == "ALARM?":
            return ",".join(str(x) for x in (len(s.alarms), *s.alarms))
        if text == "TYPE?":
            return f"{'T,T' if s.humidity else 'T'},P300,{s.max_temp_c:.1f}"
        if text == "ROM?":
            return "SIM-P300 1.00"
        if text.endswith("?"):
            raise _Refused("CMD ERR")
        return "OK:" + self._setting(text)

    def _setting(self, text: str) -> str:
        s = self.setup
        head, _, arg = text.partition(",")
        head, arg = head.strip(), arg.strip()
        if head not in ("TEMP", "MODE", "POWER"):
            raise _Refused("CMD ERR")
        if s.key_protect:
            raise _Refused("PROTECT ON")
        if head == "TEMP":
            m = re.fullmatch(r"S(-?\d+(?:\.\d)?)", arg)
            if m is None:
                raise _Refused("PARA ERR")
            sp_c = float(m.group(1))
            if not s.lower_limit_c <= sp_c <= s.upper_limit_c:
                raise _Refused("DATA OUT OF RANGE")
            self.constant_sp_c = sp_c
            if s.mode != "RUN":  # a running program owns the setpoint
                self.physics.setpoint_c = sp_c
            return text
        if head == "MODE":
            if arg not in ("CONSTANT", "STANDBY", "OFF"):
                raise _Refused("PARA ERR")
            if s.mode == "OFF" and arg != "OFF":
                raise _Refused("CHB NOT READY")  # from OFF the controller needs POWER,ON
            s.mode = arg
        else:  # POWER
            if arg not in ("ON", "OFF"):
                raise _Refused("PARA ERR")
            s.mode = "CONSTANT" if arg == "ON" else "OFF"
        self._apply_mode()
        return text

    def _apply_mode(self) -> None:
        p, mode = self.physics, self.setup.mode
        p.running = mode in ("CONSTANT", "RUN")
        if mode == "CONSTANT":
            p.setpoint_c = self.constant_sp_c
        # Constant mode has no ramp: the chamber steps at its own rate.
        p.ramp_c_per_min = 0.0


class _Refused(Exception):
    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass
class EspecServer:
    """A listening twin; ``url`` is what a rig config's ``chamber.url`` names."""

    controller: EspecController
    listener: LineServer

    @property
    def host(self) -> str:
        return self.listener.host

    @property
    def port(self) -> int:
        return self.listener.port

    @property
    def url(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    async def stop(self) -> None:
        await self.listener.stop()


async def start_espec_server(controller: EspecController, *, host: str = "127.0.0.1",
                             port: int = 0,
                             rng: np.random.Generator | None = None) -> EspecServer:
    """Serve ``controller`` on TCP, one command line at a time per connection; the
    physics' :class:`~simulators.faults.SimFaults` ``p_no_reply`` / ``p_drop`` apply."""
    draw = rng if rng is not None else np.random.default_rng(0)

    async def serve_client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while True:
            try:
                raw = await reader.readuntil(b"\r\n")
            except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError):
                return
            faults = controller.physics.faults
            if faults.p_drop and draw.random() < faults.p_drop:
                return
            if faults.p_no_reply and draw.random() < faults.p_no_reply:
                continue
            reply = controller.answer(raw.decode("ascii", "replace"))
            if reply is not None:
                writer.write(reply.encode("ascii") + b"\r\n")
                await writer.drain()

    return EspecServer(controller, await start_line_server(serve_client, host=host, port=port))
