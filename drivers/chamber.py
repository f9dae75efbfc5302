"""Chamber controller driver: :class:`drivers.protocols.Chamber` over a :class:`ChamberMap`."""

from __future__ import annotations

from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.protocols import ChamberStatus
from drivers.registermaps import ChamberMap, bits_to_names


class ModbusChamber:
    """Any chamber controller whose registers a :class:`ChamberMap` describes."""

    def __init__(self, link: ModbusLink, regmap: ChamberMap) -> None:
        self.link = link
        self.regmap = regmap

    @property
    def range_c(self) -> tuple[float, float]:
        return self.regmap.range_c

    async def read_status(self) -> ChamberStatus:
        m = self.regmap
        pv, sp, wsp, ramp, run, alarm_word = await self.link.read_fields(
            m.fields(), m.block_read_max_gap)
        alarms = int(alarm_word)
        return ChamberStatus(
            process_c=pv,
            setpoint_c=sp,
            working_setpoint_c=wsp,
            ramp_c_per_min=ramp,
            running=bool(run),
            alarms=bits_to_names(alarms, m.alarm_bits),
        )

    async def read_process_c(self) -> float:
        """Only the air temperature (PV), °C: one register read."""
        return await self.link.read_field(self.regmap.process_c)

    async def set_setpoint(self, setpoint_c: float) -> None:
        lo, hi = self.range_c
        if not lo <= setpoint_c <= hi:
            raise ValueOutOfRange(
                self.link.device, f"setpoint {setpoint_c} °C outside {lo}…{hi} °C")
        await self.link.write_field(self.regmap.setpoint_c, setpoint_c)

    async def set_ramp_rate(self, ramp_c_per_min: float) -> None:
        if ramp_c_per_min < 0:
            raise ValueOutOfRange(self.link.device, f"ramp rate {ramp_c_per_min} °C/min < 0")
        await self.link.write_field(self.regmap.ramp_c_per_min, ramp_c_per_min)

    async def run(self) -> None:
        await self.link.write_field(self.regmap.run, 1)

    async def stop(self) -> None:
        await self.link.write_field(self.regmap.run, 0)

    async def close(self) -> None:
        """Release the connection (the controller keeps running its last command)."""
        await self.link.close()
