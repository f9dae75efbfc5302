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

    def __post_init__(self) -> None:
        now = self.clock.now()
        self._moves = [_AxisMove(0.0, 0.0, now, self.slew_deg_per_s, self.accel_deg_per_s2)
                       for _ in range(self.n_axes)]
        self._done_s = now

    def move_to(self, targets_deg: tuple[float, ...]) -> None:
        now = self.clock.now()
        start = self.true_angles_deg()
        self._moves = [_AxisMove(s, float(t), now, self.slew_deg_per_s, self.accel_deg_per_s2)
                       for s, t in zip(start, targets_deg, strict=True)]
        self._done_s = now + max(m.duration_s() for m in self._moves)

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
