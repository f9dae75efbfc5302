"""Turntable driver: :class:`drivers.protocols.Turntable` over a :class:`TurntableMap`."""

from __future__ import annotations

from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.protocols import TurntableStatus
from drivers.registermaps import (
    COMMAND_MOVE,
    COMMAND_STOP,
    STATUS_IN_POSITION,
    STATUS_MOVING,
    TurntableMap,
    bits_to_names,
)


class ModbusTurntable:
    """A 2- or 3-axis positioner speaking the soakcal table map (docs/registers.md)."""

    def __init__(self, link: ModbusLink, regmap: TurntableMap, n_axes: int | None = None) -> None:
        self.link = link
        self.regmap = regmap
        self._n_axes = n_axes or regmap.n_axes

    @property
    def n_axes(self) -> int:
        return self._n_axes

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        if len(angles_deg) != self.n_axes:
            raise ValueOutOfRange(
                self.link.device, f"{len(angles_deg)} angles given, table has {self.n_axes} axes")
        words: list[int] = []
        for angle in angles_deg:
            words += self.regmap.target_deg.encode(float(angle))
        # Targets of all axes in one write, then the command: the table never sees half a move.
        await self.link.write_registers(self.regmap.target_deg.address, words)
        await self.link.write_field(self.regmap.command, COMMAND_MOVE)

    async def read_status(self) -> TurntableStatus:
        m = self.regmap
        fields = [m.axis_field(m.position_deg, i) for i in range(self.n_axes)]
        *angles, status, faults = await self.link.read_fields(
            [*fields, m.status, m.faults], max_gap_words=m.block_read_max_gap)
        status, faults = int(status), int(faults)
        return TurntableStatus(
            angles_deg=tuple(angles),
            in_position=bool(status & STATUS_IN_POSITION),
            moving=bool(status & STATUS_MOVING),
            faults=bits_to_names(faults, m.fault_bits),
        )

    async def stop(self) -> None:
        await self.link.write_field(self.regmap.command, COMMAND_STOP)

    async def close(self) -> None:
        """Release the connection (does not stop the table)."""
        await self.link.close()
