"""Turntable driver: :class:`drivers.protocols.Turntable` over a :class:`TurntableMap`.

Two layouts (docs/registers.md, "Turntable maps"): soakcal's own (all axes on one unit
id at ``base + axis × stride``, targets then a command word), and a drive per axis
(``[axes] unit_ids``), each moved by the map's ``[[sequence.move]]`` (e.g. a Leadshine
PR0 block then its trigger), homed by ``[[sequence.home]]`` and stopped by
``[[sequence.stop]]``.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import TypeVar

from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.protocols import TurntableStatus
from drivers.registermaps import Field, SequenceStep, TurntableMap, bits_to_names

T = TypeVar("T")


class ModbusTurntable:
    """A 1- to 3-axis positioner whose registers a :class:`TurntableMap` describes."""

    def __init__(self, link: ModbusLink, regmap: TurntableMap, n_axes: int | None = None) -> None:
        self.link = link
        self.regmap = regmap
        self._n_axes = n_axes or regmap.n_axes
        # What the last move commanded: the reported angles of a drive without readback.
        self._commanded: tuple[float, ...] = tuple(0.0 for _ in range(self._n_axes))

    @property
    def n_axes(self) -> int:
        return self._n_axes

    @property
    def safe_angles_deg(self) -> tuple[float, ...]:
        """Where the table rests at the end of a campaign: the map's ``[safe]`` (else home)."""
        safe = tuple(self.regmap.safe_angles_deg[: self.n_axes])
        return safe if len(safe) == self.n_axes else tuple(0.0 for _ in range(self.n_axes))

    async def _on_unit(self, axis: int, call: Callable[[], Awaitable[T]]) -> T:
        """Run ``call`` addressed to axis ``axis``' unit id (a drive per axis on one bus).

        One link (one serial line or socket) serves every drive: the unit id is the
        request's address, switched per request and restored, never two requests at once
        (this driver awaits each before the next).
        """
        if not self.regmap.unit_ids:
            return await call()
        base = self.link.device_id
        self.link.device_id = self.regmap.axis_unit(axis, base)
        try:
            return await call()
        finally:
            self.link.device_id = base

    async def _write_steps(self, axis: int, steps: tuple[SequenceStep, ...],
                           target: float = 0.0) -> None:
        """One sequence on one axis; consecutive holding registers go in one FC 16 write,
        as a drive's manual frames them (e.g. the Leadshine PR0 block and its trigger)."""
        m = self.regmap
        runs: list[tuple[int, list[int]]] = []
        singles: list[tuple[Field, float]] = []
        for step in steps:
            f = m.axis_field(step.field, axis)
            value = step.word_value(target)
            if f.table != "holding" or f.single_write:
                singles.append((f, value))  # kept in order below
                runs.append((-1, [len(singles) - 1]))
                continue
            words = f.encode(value)
            if runs and runs[-1][0] >= 0 and runs[-1][0] + len(runs[-1][1]) == f.address:
                runs[-1][1].extend(words)
            else:
                runs.append((f.address, words))
        for address, words in runs:
            if address < 0:
                f, value = singles[words[0]]
                await self._on_unit(axis, lambda f=f, v=value: self.link.write_field(f, v))
            else:
                await self._on_unit(axis, lambda a=address, w=words:
                                    self.link.write_registers(a, w))

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        if len(angles_deg) != self.n_axes:
            raise ValueOutOfRange(
                self.link.device, f"{len(angles_deg)} angles given, table has {self.n_axes} axes")
        m = self.regmap
        bad = [a for a in angles_deg if not math.isfinite(a) or abs(a) > m.range_deg]
        if bad:
            raise ValueOutOfRange(self.link.device,
                                  f"target {bad[0]}° outside ±{m.range_deg}° of the map")
        self._commanded = tuple(float(a) for a in angles_deg)
        move = m.sequences.get("move")
        if move is not None:  # a drive per axis: its block, then its trigger
            for i, angle in enumerate(angles_deg):
                await self._write_steps(i, move, float(angle))
            return
        assert m.command is not None  # the loader requires one without [[sequence.move]]
        words: list[int] = []
        for i, angle in enumerate(angles_deg):
            f = m.axis_field(m.target_deg, i)
            words += f.encode(float(angle))
            # Axes with a stride wider than the field leave a gap the write must keep.
            words += [0] * (m.axis_stride - f.n_registers) if i < self.n_axes - 1 else []
        # Targets of all axes in one write, then the command: the table never sees half a move.
        # The targets are levels (the link may repeat them); the command is an action, sent
        # again only after DEVICE BUSY: a repeated edge restarts or faults some positioners.
        await self.link.write_registers(m.target_deg.address, words, idempotent=True)
        await self.link.write_field(m.command, m.move_value)

    async def home(self) -> None:
        """Start every axis' homing (the map's ``[[sequence.home]]``); ``read_status().homed``
        says when all are done. A map without one cannot home: :class:`ValueOutOfRange`."""
        home = self.regmap.sequences.get("home")
        if home is None:
            raise ValueOutOfRange(self.link.device, f"the map {self.regmap.name} has no "
                                  "[[sequence.home]]: home the table at the drive")
        for i in range(self.n_axes):
            await self._write_steps(i, home)
        self._commanded = tuple(0.0 for _ in range(self.n_axes))

    async def read_status(self) -> TurntableStatus:
        m = self.regmap
        if m.unit_ids:
            return await self._read_status_per_unit()
        assert m.position_deg is not None  # absent only with a drive per axis (unit_ids)
        fields = [m.axis_field(m.position_deg, i) for i in range(self.n_axes)]
        extra = [m.status] + ([m.faults] if m.faults is not None else [])
        values = await self.link.read_fields([*fields, *extra],
                                             max_gap_words=m.block_read_max_gap)
        angles = values[: self.n_axes]
        status = int(values[self.n_axes])
        faults = int(values[self.n_axes + 1]) if m.faults is not None else 0
        return self._status(tuple(angles), [status], [faults])

    async def _read_status_per_unit(self) -> TurntableStatus:
        m = self.regmap
        angles: list[float] = []
        words: list[int] = []
        faults: list[int] = []
        for i in range(self.n_axes):
            fields = ([m.axis_field(m.position_deg, i)] if m.position_deg is not None else [])
            fields += [m.axis_field(m.status, i)]
            fields += [m.axis_field(m.faults, i)] if m.faults is not None else []
            values = await self._on_unit(i, lambda fs=fields: self.link.read_fields(
                fs, max_gap_words=m.block_read_max_gap))
            if m.position_deg is not None:
                angles.append(values.pop(0))
            words.append(int(values[0]))
            faults.append(int(values[1]) if m.faults is not None else 0)
        if m.position_deg is None:  # no documented readback: the commanded angles
            angles = list(self._commanded)
        return self._status(tuple(angles), words, faults)

    def _status(self, angles: tuple[float, ...], words: list[int],
                faults: list[int]) -> TurntableStatus:
        """Every axis in position (all drives), any moving; faults of every drive."""
        m = self.regmap
        in_pos = all(w >> m.in_position_bit & 1 for w in words)
        moving = (any(w >> m.moving_bit & 1 for w in words) if m.moving_bit is not None
                  else not in_pos)
        homed = (all(w >> m.homed_bit & 1 for w in words) if m.homed_bit is not None
                 else None)
        names: list[str] = []
        for i, (word, status) in enumerate(zip(faults, words, strict=True)):
            prefix = f"axis {i}: " if len(faults) > 1 else ""
            names += [prefix + n for n in bits_to_names(word, m.fault_bits)]
            names += [prefix + n for b, n in sorted(m.status_bits.items())
                      if n.startswith("fault") and status >> b & 1]
        return TurntableStatus(angles_deg=angles, in_position=bool(in_pos), moving=bool(moving),
                               faults=tuple(names), homed=homed)

    async def read_identity(self) -> float | None:
        """The map's identity register (``None`` when the map has none)."""
        ident = self.regmap.identity
        if ident is None:
            return None
        return await self.link.read_field(ident.field)

    async def stop(self) -> None:
        """Halt: ``[command] stop``, else every axis' ``[[sequence.stop]]``. A map with
        neither (a drive whose stop is not documented) writes nothing; :meth:`park` says so."""
        m = self.regmap
        if m.command is not None:
            await self.link.write_field(m.command, m.stop_value)
            return
        stop = m.sequences.get("stop")
        for i in range(self.n_axes if stop is not None else 0):
            await self._write_steps(i, stop)  # type: ignore[arg-type]

    @property
    def can_stop(self) -> bool:
        return self.regmap.command is not None or "stop" in self.regmap.sequences

    async def close(self) -> None:
        """Release the connection (does not stop the table)."""
        await self.link.close()

    async def park(self) -> str:
        """The table's safe state (:meth:`drivers.protocols.Turntable.park`): stopped, then
        sent to the map's ``[safe] angles_deg`` (home when the map has none)."""
        await self.stop()
        rest = self.safe_angles_deg
        await self.move_to(rest)
        how = "stopped" if self.can_stop else "no stop in the map (undocumented)"
        return f"{how}, sent to (" + ", ".join(f"{a:g}" for a in rest) + ")°"
