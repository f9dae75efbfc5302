"""Turntable physics (trapezoidal slew, settle, in-position) and its Modbus register image.

Positions are analytic in time, so "integrate on read" is just evaluating the
motion profile at ``clock.now()``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pymodbus.constants import ExcCodes

from drivers.clock import Clock
from drivers.registermaps import TurntableMap
from simulators.faults import SimFaults
from simulators.modbus_server import read_block


@dataclass
class _AxisMove:
    start_deg: float
    target_deg: float
    t0_s: float
    slew_deg_per_s: float
    accel_deg_per_s2: float

    def duration_s(self) -> float:
        d = abs(self.target_deg - self.start_deg)
        v, a = self.slew_deg_per_s, self.accel_deg_per_s2
        if d <= v * v / a:  # triangular profile: never reaches slew rate
            return 2.0 * math.sqrt(d / a)
        return d / v + v / a

    def position_at(self, t_s: float) -> float:
        d_total = self.target_deg - self.start_deg
        d, sign = abs(d_total), math.copysign(1.0, d_total)
        v, a = self.slew_deg_per_s, self.accel_deg_per_s2
        tau = max(0.0, t_s - self.t0_s)
        T = self.duration_s()
        if tau >= T:
            return self.target_deg
        if d <= v * v / a:
            v = math.sqrt(d * a)  # peak speed of the triangle
        t_acc = v / a
        if tau < t_acc:
            s = 0.5 * a * tau * tau
        elif tau < T - t_acc:
            s = 0.5 * a * t_acc * t_acc + v * (tau - t_acc)
        else:
            r = T - tau
            s = d - 0.5 * a * r * r
        return self.start_deg + sign * s


@dataclass
class TurntablePhysics:
    """Axes slewing with rate and acceleration limits, then settling before in-position."""

    clock: Clock
    n_axes: int = 3
    slew_deg_per_s: float = 20.0
    accel_deg_per_s2: float = 40.0
    settle_s: float = 2.0
    encoder_error_deg: tuple[float, ...] = ()  # constant readback error per axis
    faults: SimFaults = field(default_factory=SimFaults)
    _moves: list[_AxisMove] = field(init=False)
    _done_s: float = field(init=False)

    # Each axis' homing state: True once its homing ran (a drive per axis; the twin's own
    # table layout has no homing and ignores it). ``homed_at_start`` sets the power-up state.
    homed_at_start: bool = True
    # A drive that was never commanded reports its command done (in position) at power-up;
    # False keeps the twin's own table settling for ``settle_s`` first, as it always has.
    settled_at_start: bool = False
    _homed: list[bool] = field(init=False)
    _homing: list[bool] = field(init=False)

    def __post_init__(self) -> None:
        now = self.clock.now() - (self.settle_s if self.settled_at_start else 0.0)
        self._moves = [_AxisMove(0.0, 0.0, now, self.slew_deg_per_s, self.accel_deg_per_s2)
                       for _ in range(self.n_axes)]
        self._done_s = now
        self._homed = [self.homed_at_start] * self.n_axes
        self._homing = [False] * self.n_axes

    def move_to(self, targets_deg: tuple[float, ...]) -> None:
        now = self.clock.now()
        start = self.true_angles_deg()
        self._moves = [_AxisMove(s, float(t), now, self.slew_deg_per_s, self.accel_deg_per_s2)
                       for s, t in zip(start, targets_deg, strict=True)]
        self._done_s = now + max(m.duration_s() for m in self._moves)

    def move_axis(self, axis: int, target_deg: float) -> None:
        """One axis' drive was triggered (a drive per axis); the others keep their motion."""
        now = self.clock.now()
        self._homing[axis] = False
        self._moves[axis] = _AxisMove(self._moves[axis].position_at(now), float(target_deg),
                                      now, self.slew_deg_per_s, self.accel_deg_per_s2)
        self._done_s = max(m.t0_s + m.duration_s() for m in self._moves)

    def home_axis(self, axis: int) -> None:
        """Homing: the axis runs to its home switch (true 0°) and is homed once there."""
        self.move_axis(axis, 0.0)
        self._homing[axis] = True

    def stop_axis(self, axis: int) -> None:
        self.move_axis(axis, self._moves[axis].position_at(self.clock.now()))

    def axis_moving(self, axis: int) -> bool:
        m = self._moves[axis]
        return self.clock.now() < m.t0_s + m.duration_s()

    def axis_in_position(self, axis: int) -> bool:
        if self.faults.never_in_position:
            return False
        m = self._moves[axis]
        return self.clock.now() >= m.t0_s + m.duration_s() + self.settle_s

    def axis_homed(self, axis: int) -> bool:
        if self._homing[axis] and self.axis_in_position(axis):
            self._homing[axis], self._homed[axis] = False, True
        return self._homed[axis]

    def stop(self) -> None:
        """Halt where the axes are now (a real table decelerates; the difference is moot here)."""
        here = self.true_angles_deg()
        self.move_to(here)

    def true_angles_deg(self) -> tuple[float, ...]:
        now = self.clock.now()
        return tuple(m.position_at(now) for m in self._moves)

    def reported_angles_deg(self) -> tuple[float, ...]:
        err = self.encoder_error_deg or (0.0,) * self.n_axes
        return tuple(a + e for a, e in zip(self.true_angles_deg(), err, strict=False))

    def moving(self) -> bool:
        return self.clock.now() < self._done_s

    def in_position(self) -> bool:
        if self.faults.never_in_position:
            return False
        return self.clock.now() >= self._done_s + self.settle_s


class TurntableRegisterImage:
    """Renders :class:`TurntablePhysics` into a :class:`TurntableMap` and applies writes."""

    def __init__(self, physics: TurntablePhysics, regmap: TurntableMap,
                 identity_value: float | None = None) -> None:
        self.physics = physics
        self.regmap = regmap
        ident = regmap.identity
        self._identity_words: dict[int, int] = {}
        if ident is not None:
            value = ident.expect if identity_value is None else identity_value
            self._identity_words = {ident.field.address + k: w
                                    for k, w in enumerate(ident.field.encode(value))}
        for check in regmap.checks:  # registers the map checks read what it expects
            self._identity_words.update({check.field.address + k: w for k, w in
                                         enumerate(check.field.encode(check.expect))})
        m = regmap
        self._targets: list[float] = [0.0] * physics.n_axes
        self._target_addrs = {
            m.axis_field(m.target_deg, i).address + k: (i, k)
            for i in range(physics.n_axes) for k in range(m.target_deg.n_registers)
        }
        self._target_words: dict[int, int] = {a: 0 for a in self._target_addrs}

    def read(self, address: int, count: int) -> list[int] | ExcCodes:
        p, m = self.physics, self.regmap
        image: dict[int, int] = dict(self._target_words)
        for i, angle in enumerate(p.reported_angles_deg()):
            f = m.axis_field(m.position_deg, i)
            for k, w in enumerate(f.encode(angle)):
                image[f.address + k] = w
        status = (1 << m.in_position_bit if p.in_position() else 0) | (
            1 << m.moving_bit if p.moving() else 0)
        image[m.status.address] = status
        if m.faults is not None:
            image[m.faults.address] = 0
        image[m.command.address] = 0
        image.update(self._identity_words)
        return read_block(image, address, count)

    def write(self, address: int, values: list[int]) -> None | ExcCodes:
        m = self.regmap
        addrs = range(address, address + len(values))
        if all(a in self._target_addrs for a in addrs):
            for a, w in zip(addrs, values, strict=True):
                self._target_words[a] = w
            return None
        if address == m.command.address and len(values) == 1:
            if values[0] == m.move_value:
                targets = []
                for i in range(self.physics.n_axes):
                    f = m.axis_field(m.target_deg, i)
                    targets.append(f.decode([self._target_words[f.address + k]
                                             for k in range(f.n_registers)]))
                if any(not math.isfinite(t) or abs(t) > m.range_deg for t in targets):
                    return ExcCodes.ILLEGAL_VALUE
                self.physics.move_to(tuple(targets))
                return None
            if values[0] == m.stop_value:
                self.physics.stop()
                return None
            return ExcCodes.ILLEGAL_VALUE
        return ExcCodes.ILLEGAL_ADDRESS


class DriveAxisImage:
    """One axis of :class:`TurntablePhysics` as the drive a map with ``[axes] unit_ids``
    describes: served on that axis' unit id, moved by the map's ``[[sequence.move]]``.

    Writes are kept as written; a write of the last step of a sequence (its register
    and value: the trigger) plays it: ``move`` decodes the target from the kept words,
    ``home`` runs the axis to its home switch, ``stop`` halts it. Status carries the
    map's ``in_position``, ``moving`` and ``homed`` bits; the position readback (when the
    map has one) the reported angle.
    """

    def __init__(self, physics: TurntablePhysics, regmap: TurntableMap, axis: int) -> None:
        self.physics, self.regmap, self.axis = physics, regmap, axis
        m = regmap
        self._words: dict[int, int] = {}
        for f in m.registers.values():  # every register of the drive reads (0 unless set)
            for k in range(f.n_registers):
                self._words[m.axis_field(f, axis).address + k] = 0
        for check in m.checks:  # registers the map checks read what it expects
            f = m.axis_field(check.field, axis)
            self._words.update({f.address + k: w for k, w in enumerate(f.encode(check.expect))})
        if m.identity is not None:
            f = m.axis_field(m.identity.field, axis)
            self._words.update({f.address + k: w
                                for k, w in enumerate(f.encode(m.identity.expect))})
        # A status bit named "enabled" reads set: the twin's drives are enabled.
        self._enabled_mask = sum(1 << b for b, n in m.status_bits.items() if n == "enabled")
        self._triggers: dict[tuple[int, int], str] = {}
        for name, steps in m.sequences.items():
            last = steps[-1]
            f = m.axis_field(last.field, axis)
            word = f.encode(last.word_value(0.0))[-1] if last.source is None else None
            self._triggers[(f.address + f.n_registers - 1, -1 if word is None else word)] = name

    def read(self, address: int, count: int) -> list[int] | ExcCodes:
        p, m, i = self.physics, self.regmap, self.axis
        image = dict(self._words)
        if m.position_deg is not None:
            f = m.axis_field(m.position_deg, i)
            angle = p.reported_angles_deg()[i]
            image.update({f.address + k: w for k, w in enumerate(f.encode(angle))})
        status = 1 << m.in_position_bit if p.axis_in_position(i) else 0
        if m.moving_bit is not None and p.axis_moving(i):
            status |= 1 << m.moving_bit
        if m.homed_bit is not None and p.axis_homed(i):
            status |= 1 << m.homed_bit
        status |= self._enabled_mask  # the drive is enabled (a bit the driver only shows)
        image[m.axis_field(m.status, i).address] = status
        return read_block(image, address, count)

    def write(self, address: int, values: list[int]) -> None | ExcCodes:
        addrs = range(address, address + len(values))
        if not all(a in self._words for a in addrs):
            return ExcCodes.ILLEGAL_ADDRESS
        played: str | None = None
        for a, w in zip(addrs, values, strict=True):
            self._words[a] = w
            played = self._triggers.get((a, w), self._triggers.get((a, -1), played))
        if played is not None:
            return self._play(played)
        return None

    def _play(self, name: str) -> None | ExcCodes:
        p, m, i = self.physics, self.regmap, self.axis
        if name == "move":
            f = m.axis_field(m.target_deg, i)
            target = f.decode([self._words[f.address + k] for k in range(f.n_registers)])
            if not math.isfinite(target) or abs(target) > m.range_deg:
                return ExcCodes.ILLEGAL_VALUE
            p.move_axis(i, target)
        elif name == "home":
            p.home_axis(i)
        else:
            p.stop_axis(i)
        return None


def drive_images(physics: TurntablePhysics, regmap: TurntableMap) -> dict[int, DriveAxisImage]:
    """Unit id → the drive of each axis (a map with ``[axes] unit_ids``)."""
    return {regmap.unit_ids[i]: DriveAxisImage(physics, regmap, i)
            for i in range(min(physics.n_axes, regmap.n_axes))}
