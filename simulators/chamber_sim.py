"""Chamber physics (air and sensor die) and its Modbus register image.

Physics integrates on read: :meth:`ChamberPhysics.advance_to` brings the state
to ``clock.now()`` lazily whenever a register is read or written, in substeps
no longer than ``max_step_s`` so the ramp, the air lag and the die lag compose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from pymodbus.constants import ExcCodes

from calibration.thermal_plant import AMBIENT_C, lag_step, rate_limited
from drivers.clock import Clock
from drivers.registermaps import ChamberMap, Field
from simulators.faults import SimFaults
from simulators.modbus_server import read_block

# The die counts as moving (its hysteresis direction set) above this rate: 0.01 °C/min.
DIRECTION_RATE_C_PER_S = 0.01 / 60.0

# Simulated condition -> the names a map may give its bit, first match wins.
ALARM_ALIASES: dict[str, tuple[str, ...]] = {
    "deviation_high": ("deviation_high", "alarm_1"),
    "deviation_low": ("deviation_low", "alarm_2"),
}


@dataclass
class ChamberPhysics:
    """Air temperature under a ramping working setpoint, and a sensor die lagging the air.

    * The working setpoint (WSP) moves towards SP at ``ramp_c_per_min`` (0 = step).
    * The air follows WSP first-order with ``air_tau_s``, never faster than the
      chamber's own capability ``max_rate_c_per_min``; no overshoot.
    * Stopped, the air relaxes to ``ambient_c`` with ``off_tau_s``.
    * The die follows the air first-order with ``die_tau_s`` (mounting + package).

    The steps are ``calibration.thermal_plant``'s, shared with the offline twin and the
    diagnosis.
    """

    clock: Clock
    rng: np.random.Generator
    air_c: float = AMBIENT_C
    setpoint_c: float = AMBIENT_C
    ramp_c_per_min: float = 1.0
    running: bool = False
    ambient_c: float = AMBIENT_C
    air_tau_s: float = 60.0
    off_tau_s: float = 1800.0
    max_rate_c_per_min: float = 5.0
    die_tau_s: float = 900.0
    # Manual mode: the controller holds its output; WSP stays put, SP is stored but not followed.
    manual: bool = False
    pv_noise_c: float = 0.02
    deviation_alarm_c: float = 5.0
    max_step_s: float = 2.0
    faults: SimFaults = field(default_factory=SimFaults)
    working_setpoint_c: float = field(init=False)
    die_c: float = field(init=False)
    # The die's dT/dt over the last integration substep (°C/s) and the direction of its last
    # excursion (+1 heating, −1 cooling, 0 none yet): what a rate-sensitive or hysteretic
    # sensor's output depends on (simulators.truth.Context), kept as the die moves.
    die_rate_c_per_s: float = field(init=False, default=0.0)
    die_direction: int = field(init=False, default=0)
    t_s: float = field(init=False)
    _stuck_pv_c: float | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.working_setpoint_c = self.air_c
        self.die_c = self.air_c
        self.t_s = self.clock.now()

    # --- public -------------------------------------------------------------
    def advance_to(self, t_s: float | None = None) -> None:
        """Integrate from the last update to ``t_s`` (default: now)."""
        t_end = self.clock.now() if t_s is None else t_s
        while self.t_s < t_end:
            dt = min(self.max_step_s, t_end - self.t_s)
            self._step(dt)
            self.t_s += dt

    def process_value_c(self) -> float:
        """What the controller's PV register shows: air + measurement noise, or stuck."""
        if self.faults.stuck_process_value:
            if self._stuck_pv_c is None:
                self._stuck_pv_c = self.air_c
            return self._stuck_pv_c
        self._stuck_pv_c = None
        return self.air_c + float(self.rng.normal(0.0, self.pv_noise_c))

    def alarm_bits(self) -> int:
        if not self.running:
            return 0
        dev = self.air_c - self.working_setpoint_c
        return (1 if dev > self.deviation_alarm_c else 0) | (
            2 if dev < -self.deviation_alarm_c else 0)

    def die_now_c(self) -> float:
        """The die's temperature (°C) at the clock's now: what a sensor's capture reads."""
        self.advance_to()
        return self.die_c

    def die_motion_now(self) -> tuple[float, int]:
        """(the die's dT/dt in °C/s, the direction of its last excursion) at the clock's now:
        what a capture's hysteresis and rate terms read (simulators.bridge_sim)."""
        self.advance_to()
        return self.die_rate_c_per_s, self.die_direction

    # --- internals -----------------------------------------------------------
    def _step(self, dt: float) -> None:
        if self.running and self.manual:
            target, tau = self.air_c, self.air_tau_s  # output held: the air stays where it is
        elif self.running:
            max_dw = self.ramp_c_per_min / 60.0 * dt if self.ramp_c_per_min > 0 else math.inf
            self.working_setpoint_c = rate_limited(self.working_setpoint_c, self.setpoint_c,
                                                   max_dw)
            target, tau = self.working_setpoint_c, self.air_tau_s
        else:
            # Stopped: WSP tracks PV like a real controller in standby.
            self.working_setpoint_c = self.air_c
            target, tau = self.ambient_c, self.off_tau_s
        new_air = float(lag_step(self.air_c, target, dt, tau))
        new_air = rate_limited(self.air_c, new_air, self.max_rate_c_per_min / 60.0 * dt)
        # Die: exact first-order step for the mean air over the substep.
        mean_air = 0.5 * (self.air_c + new_air)
        new_die = float(lag_step(self.die_c, mean_air, dt, self.die_tau_s))
        self.die_rate_c_per_s = (new_die - self.die_c) / dt if dt > 0 else 0.0
        if abs(self.die_rate_c_per_s) > DIRECTION_RATE_C_PER_S:
            self.die_direction = 1 if self.die_rate_c_per_s > 0 else -1
        self.die_c = new_die
        self.air_c = new_air


@dataclass(frozen=True)
class ControllerSetup:
    """How the simulated controller is configured, whatever the map a client reads it with.

    A real controller is set up at its front panel; a lab's map file may or may not
    agree. The twin serves the map's addresses but encodes each value the way the
    controller is set up, so a map that does not match the controller reads wrong
    values exactly as it would on the bench (and the sensor die, which follows the
    real air, disagrees with them).

    * ``decimals``: the decimal-point setting of integer temperature registers
      (counts = value · 10^decimals); ``None``: as the map's ``scale`` says.
    * ``units``: ``"F"`` serves PV, SP, WSP in °F and the ramp in °F per time unit.
    * ``ramp_per``: ``"hour"``: the ramp register is degrees per hour.
    * ``swap_words``: 32-bit values in the opposite word order to the map's.
    * ``silent``: role names (``alarms``, ``working_setpoint_c``...) whose register
      answers Modbus exception 2 (illegal address), as on a model that lacks it.
    * ``mode``: ``"manual"`` holds the output (WSP and air stay put, the map's
      ``manual_mode`` status bit is set); ``"standby"`` does not control at all.
    * ``holds``: register name → the value this controller holds there, instead of
      what the map's ``[[checks]]`` expect (e.g. ``{"loop_mode": 54}``: an F4T loop in
      Manual; ``{"ramp_units": 1}``: a 3216 set to per-hour ramps).
    * ``profile_owns_setpoint``: ``(register, value)``: a profile is running and owns the
      setpoint, as on a Watlow F4: a setpoint write is stored (it reads back) but not
      followed until ``register`` is written ``value`` (the profile terminated); the
      controller then follows the last setpoint written. A map whose
      ``[[sequence.set_setpoint]]`` writes the terminate first drives it; one without does
      not move the chamber.
    * ``single_writes_only``: a multiple-register write (FC 16) is acknowledged but not
      executed, as a CSZ EZT-430i does outside its program registers (its manual, §4.9):
      only a map with ``write = "single"`` (FC 6) moves the chamber.
    """

    decimals: int | None = None
    units: Literal["C", "F"] = "C"
    ramp_per: Literal["min", "hour"] = "min"
    swap_words: bool = False
    silent: frozenset[str] = frozenset()
    mode: Literal["auto", "manual", "standby"] = "auto"
    holds: tuple[tuple[str, float], ...] = ()
    profile_owns_setpoint: tuple[str, float] | None = None
    single_writes_only: bool = False

    def served(self, f: Field, role: str) -> Field:
        """The field as this controller encodes it (the map's address, its own format)."""
        out = f
        if self.decimals is not None and f.encoding != "float32":
            out = replace(out, scale=float(10 ** self.decimals))
        if self.swap_words and f.n_registers == 2:
            out = replace(out, word_order="low_first" if f.word_order == "high_first"
                          else "high_first")
        if self.units == "F" and role in TEMPERATURE_ROLES:
            # Back to the register's own units: the map's offset is the map's business.
            out = replace(out, offset=0.0)
        return out

    def to_controller(self, value_c: float, role: str) -> float:
        """A physics value (°C, °C/min) in the controller's display units."""
        if role == "ramp_c_per_min":
            value_c *= 60.0 if self.ramp_per == "hour" else 1.0
            return value_c * 1.8 if self.units == "F" else value_c
        if role in TEMPERATURE_ROLES and self.units == "F":
            return value_c * 1.8 + 32.0
        return value_c

    def from_controller(self, value: float, role: str) -> float:
        if role == "ramp_c_per_min":
            value /= 60.0 if self.ramp_per == "hour" else 1.0
            return value / 1.8 if self.units == "F" else value
        if role in TEMPERATURE_ROLES and self.units == "F":
            return (value - 32.0) / 1.8
        return value


def _key(f: Field) -> tuple[str, int]:
    return f.table, f.address


#: Roles whose value is a temperature (°C in physics, the controller's units on the wire).
TEMPERATURE_ROLES = ("process_c", "setpoint_c", "working_setpoint_c")


class ChamberRegisterImage:
    """Renders :class:`ChamberPhysics` into any :class:`ChamberMap` and applies writes.

    The registers the map gives a role (PV, SP, WSP, ramp, run, alarms) follow
    the physics; the identity register answers the map's expected value (or
    ``identity_value``, to play a wrong device); any other writable register
    (e.g. the F4T's ramp action) keeps what was written. A map without a run
    register is a controller that controls whenever powered: the physics runs.
    """

    #: Alarm and status bit names the twin can raise, by what the physics knows.
    SIMULATED_BITS = ("deviation_high", "deviation_low", "ramp_running", "manual_mode")

    def __init__(self, physics: ChamberPhysics, regmap: ChamberMap,
                 identity_value: float | None = None,
                 setup: ControllerSetup | None = None) -> None:
        self.physics = physics
        self.regmap = regmap
        self.setup = setup or ControllerSetup()
        self.ignores_fc16 = self.setup.single_writes_only  # read by the Modbus server
        physics.manual = self.setup.mode == "manual"
        m = regmap
        # Keys are (Modbus table, address): the four tables are separate address spaces.
        self._roles = {_key(m.setpoint_c): "setpoint_c"}
        if m.ramp_c_per_min is not None:
            self._roles[_key(m.ramp_c_per_min)] = "ramp_c_per_min"
        else:  # no static ramp: the controller steps, the air as fast as the chamber goes
            physics.ramp_c_per_min = 0.0
        # ControllerSetup.profile_owns_setpoint: the written (static) setpoint while a
        # profile owns the one the controller follows.
        self._profile_running = self.setup.profile_owns_setpoint is not None
        self._static_sp_c: float | None = None
        if self._profile_running:
            reg, _ = self.setup.profile_owns_setpoint  # type: ignore[misc]
            if reg not in m.registers:
                raise ValueError(f"profile_owns_setpoint: map {m.name} has no register {reg!r}")
        if m.run is not None:
            self._roles[_key(m.run)] = "running"
        else:
            physics.running = self.setup.mode != "standby"
        # Addresses that answer "illegal address" (ControllerSetup.silent).
        self._silent = {(f.table, a) for name in self.setup.silent
                        for f in [m.registers.get(name) or getattr(m, name, None)]
                        if isinstance(f, Field) for a in range(f.address,
                                                                f.address + f.n_registers)}
        self._identity = (identity_value if identity_value is not None
                          else m.identity.expect if m.identity is not None else None)
        role_fields = {id(f) for f in (m.process_c, m.setpoint_c, m.working_setpoint_c,
                                       m.ramp_c_per_min, m.run, m.alarms) if f is not None}
        self._stored: dict[tuple[str, int], tuple[Field, list[int]]] = {}
        # A well-set-up controller: registers the map checks read what the map expects.
        checked = {id(c.field): c.expect for c in m.checks}
        checked.update({id(a.field): float(min(a.ok)) for a in m.alarm_states})
        checked.update({id(m.registers[name]): value for name, value in self.setup.holds})
        for f in m.registers.values():
            if id(f) not in role_fields:
                value = self._identity if m.identity is not None and f is m.identity.field \
                    else checked.get(id(f), 0.0)
                self._stored[_key(f)] = (f, f.encode(value or 0.0))

    def _alarm_word(self) -> int:
        m, p = self.regmap, self.physics
        names = {n: b for b, n in {**m.alarm_bits, **m.info_bits}.items()}
        bits = p.alarm_bits()
        raised = {"deviation_high": bool(bits & 1), "deviation_low": bool(bits & 2),
                  "ramp_running": p.running and abs(p.working_setpoint_c - p.setpoint_c) > 1e-9,
                  "manual_mode": p.manual}
        word = 0
        for name, on in raised.items():
            # A controller whose map names user-configured alarms (Eurotherm 3216: alarm_1..4)
            # is simulated configured as a soak chamber would be: AL1 deviation high, AL2 low.
            bit = next((names[n] for n in ALARM_ALIASES.get(name, (name,)) if n in names), None)
            if on and bit is not None:
                word |= 1 << bit
        return word

    def read(self, address: int, count: int) -> list[int] | ExcCodes:
        return self.read_table("holding", address, count)

    def write(self, address: int, values: list[int]) -> None | ExcCodes:
        return self.write_table("holding", address, values)

    def read_table(self, table: str, address: int, count: int) -> list[int] | ExcCodes:
        """Words (bits as 0/1 for coils and discrete inputs) of one Modbus table."""
        p, m, cfg = self.physics, self.regmap, self.setup
        p.advance_to()
        if self._silent & {(table, a) for a in range(address, address + count)}:
            return ExcCodes.ILLEGAL_ADDRESS
        image: dict[int, int] = {}
        for (t, a), (_f, words) in self._stored.items():
            for i, w in enumerate(words):
                if t == table:
                    image[a + i] = w
        sp_c = p.setpoint_c if self._static_sp_c is None else self._static_sp_c
        rendered: list[tuple[Field, float]] = [
            (cfg.served(f, role), cfg.to_controller(value, role)) for f, role, value in (
                (m.process_c, "process_c", p.process_value_c()),
                (m.setpoint_c, "setpoint_c", sp_c),
                (m.working_setpoint_c, "working_setpoint_c", p.working_setpoint_c),
                (m.ramp_c_per_min, "ramp_c_per_min", p.ramp_c_per_min)) if f is not None
        ]
        if m.run is not None:
            rendered.append((m.run, float(m.run_on if p.running else m.run_off)))
        if m.alarms is not None:
            rendered.append((m.alarms, float(self._alarm_word())))
        for f, value in rendered:
            if f.table == table:
                for i, w in enumerate(f.encode(value)):
                    image[f.address + i] = w
        if not image:
            return ExcCodes.ILLEGAL_ADDRESS
        return read_block(image, address, count)

    def write_table(self, table: str, address: int, values: list[int]) -> None | ExcCodes:
        p, m, cfg = self.physics, self.regmap, self.setup
        p.advance_to()
        if self._silent & {(table, a) for a in range(address, address + len(values))}:
            return ExcCodes.ILLEGAL_ADDRESS
        name = self._roles.get((table, address))
        if name is None:
            stored = self._stored.get((table, address))
            if stored is None or "w" not in stored[0].access:
                return ExcCodes.ILLEGAL_ADDRESS
            if len(values) != len(stored[1]):
                return ExcCodes.ILLEGAL_VALUE
            self._stored[table, address] = (stored[0], list(values))
            self._maybe_end_profile(stored[0], values)
            return None
        f = {"setpoint_c": m.setpoint_c, "ramp_c_per_min": m.ramp_c_per_min,
             "running": m.run}[name]
        assert f is not None
        if len(values) != f.n_registers:
            return ExcCodes.ILLEGAL_VALUE
        if name == "running":
            value = f.decode(values)
        else:
            value = cfg.from_controller(cfg.served(f, name).decode(values), name)
        if name == "setpoint_c":
            lo, hi = m.range_c
            if not lo <= value <= hi:
                return ExcCodes.ILLEGAL_VALUE
            if self._profile_running:  # stored and read back, not followed
                self._static_sp_c = value
                return None
        if name == "ramp_c_per_min" and value < 0:
            return ExcCodes.ILLEGAL_VALUE
        if name == "running":
            if int(value) not in (m.run_on, m.run_off):
                return ExcCodes.ILLEGAL_VALUE
            p.running = int(value) == m.run_on
            return None
        setattr(p, name, value)
        return None

    def _maybe_end_profile(self, f: Field, values: list[int]) -> None:
        """The write that terminates the running profile (ControllerSetup.profile_owns_setpoint):
        the controller then follows the static setpoint."""
        needs = self.setup.profile_owns_setpoint
        if not self._profile_running or needs is None or self.regmap.registers[needs[0]] != f:
            return
        if f.decode(values) == needs[1]:
            self._profile_running = False
            if self._static_sp_c is not None:
                self.physics.setpoint_c = self._static_sp_c
            self._static_sp_c = None
