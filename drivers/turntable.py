"""Turntable driver: :class:`drivers.protocols.Turntable` over a :class:`TurntableMap`."""

from __future__ import annotations

import math

from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.protocols import TurntableStatus
from drivers.registermaps import TurntableMap, bits_to_names


class ModbusTurntable:
    """A 1- to 3-axis positioner whose registers a :class:`TurntableMap` describes."""

    def __init__(self, link: ModbusLink, regmap: TurntableMap, n_axes: int | None = None) -> None:
        self.link = link
        self.regmap = regmap
        self._n_axes = n_axes or regmap.n_axes

    @property
    def n_axes(self) -> int:
        return self._n_axes

    @property
    def safe_angles_deg(self) -> tuple[float, ...]:
        """Where the table rests at the end of a campaign: the map's ``[safe]`` (else home)."""
        safe = tuple(self.regmap.safe_angles_deg[: self.n_axes])
        return safe if len(safe) == self.n_axes else tuple(0.0 for _ in range(self.n_axes))

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        if len(angles_deg) != self.n_axes:
            raise ValueOutOfRange(
                self.link.device, f"{len(angles_deg)} angles given, table has {self.n_axes} axes")
        m = self.regmap
        bad = [a for a in angles_deg if not math.isfinite(a) or abs(a) > m.range_deg]
        if bad:
            raise ValueOutOfRange(self.link.device,
                                  f"target {bad[0]}° outside ±{m.range_deg}° of the map")
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

    async def read_status(self) -> TurntableStatus:
        m = self.regmap
        fields = [m.axis_field(m.position_deg, i) for i in range(self.n_axes)]
        extra = [m.status] + ([m.faults] if m.faults is not None else [])
        values = await self.link.read_fields([*fields, *extra],
                                             max_gap_words=m.block_read_max_gap)
        angles = values[: self.n_axes]
        status = int(values[self.n_axes])
        faults = int(values[self.n_axes + 1]) if m.faults is not None else 0
        return TurntableStatus(
            angles_deg=tuple(angles),
            in_position=bool(status >> m.in_position_bit & 1),
            moving=bool(status >> m.moving_bit & 1),
            faults=bits_to_names(faults, m.fault_bits),
        )

    async def read_identity(self) -> float | None:
        """The map's identity register (``None`` when the map has none)."""
        ident = self.regmap.identity
        if ident is None:
            return None
        return await self.link.read_field(ident.field)

    async def stop(self) -> None:
        await self.link.write_field(self.regmap.command, self.regmap.stop_value)

    async def close(self) -> None:
        """Release the connection (does not stop the table)."""
        await self.link.close()

    async def park(self) -> str:
        """The table's safe state (:meth:`drivers.protocols.Turntable.park`): stopped, then
        sent to the map's ``[safe] angles_deg`` (home when the map has none)."""
        await self.stop()
        rest = self.safe_angles_deg
        await self.move_to(rest)
        return "stopped, sent to (" + ", ".join(f"{a:g}" for a in rest) + ")°"
