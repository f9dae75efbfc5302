"""Chamber controller driver: :class:`drivers.protocols.Chamber` over a :class:`ChamberMap`."""

from __future__ import annotations

from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.protocols import ChamberStatus
from drivers.registermaps import ChamberMap, bits_to_names

# Largest relative difference between the ramp rate asked for and the one the register holds.
RAMP_WRITE_TOLERANCE = 0.05


class ModbusChamber:
    """Any chamber controller whose registers a :class:`ChamberMap` describes.

    Every write sets a level (setpoint, ramp rate, run/stop, setup values), so each is
    idempotent and the link may repeat it after a lost reply (drivers/modbus_link.py).
    """

    def __init__(self, link: ModbusLink, regmap: ChamberMap) -> None:
        self.link = link
        self.regmap = regmap
        self._setup_done = False

    @property
    def range_c(self) -> tuple[float, float]:
        return self.regmap.range_c

    @property
    def safe_setpoint_c(self) -> float:
        """Where the chamber is left at the end of a campaign: the map's ``[safe]``."""
        return self.regmap.safe_setpoint_c

    @property
    def stop_when_safe(self) -> bool:
        """The map's ``[safe] stop``: the park also stops the controller."""
        return self.regmap.safe_stop

    async def read_status(self) -> ChamberStatus:
        m = self.regmap
        values = await self.link.read_fields(m.fields(), m.block_read_max_gap)
        pv, sp, wsp, ramp = values[:4]
        rest = values[4:]
        # A map without a run register describes a controller that controls whenever powered.
        running = True
        if m.run is not None:
            running = int(rest.pop(0)) == m.run_on
        alarms: tuple[str, ...] = ()
        if m.alarms is not None:
            word = int(rest.pop(0))
            # Only the bits the map names as alarms count; informative bits are not faults.
            mask = sum(1 << b for b in m.alarm_bits) if m.alarm_bits else 0xFFFF
            alarms = bits_to_names(word & mask & ~sum(1 << b for b in m.info_bits),
                                   m.alarm_bits)
        for state in m.alarm_states:  # enumerated alarm registers, read one by one
            active = state.alarm(await self.link.read_field(state.field))
            if active is not None:
                alarms += (active,)
        return ChamberStatus(
            process_c=pv,
            setpoint_c=sp,
            working_setpoint_c=wsp,
            ramp_c_per_min=ramp,
            running=running,
            alarms=alarms,
        )

    async def read_process_c(self) -> float:
        """Only the air temperature (PV), °C: one register read."""
        return await self.link.read_field(self.regmap.process_c)

    async def read_identity(self) -> float | None:
        """The map's identity register (``None`` when the map has none)."""
        ident = self.regmap.identity
        if ident is None:
            return None
        return await self.link.read_field(ident.field)

    async def read_info_bits(self) -> tuple[str, ...]:
        """Informative status bits the map names (manual mode, ramp running, ...)."""
        m = self.regmap
        if m.alarms is None or not m.info_bits:
            return ()
        word = int(await self.link.read_field(m.alarms))
        return tuple(n for b, n in sorted(m.info_bits.items()) if word >> b & 1)

    async def set_setpoint(self, setpoint_c: float) -> None:
        lo, hi = self.range_c
        if not lo <= setpoint_c <= hi:
            raise ValueOutOfRange(
                self.link.device, f"setpoint {setpoint_c} °C outside {lo}…{hi} °C")
        await self.link.write_field(self.regmap.setpoint_c, setpoint_c, idempotent=True)

    async def set_ramp_rate(self, ramp_c_per_min: float) -> None:
        if ramp_c_per_min < 0:
            raise ValueOutOfRange(self.link.device, f"ramp rate {ramp_c_per_min} °C/min < 0")
        limit = self.regmap.max_ramp_c_per_min
        if limit is not None and ramp_c_per_min > limit:
            raise ValueOutOfRange(self.link.device,
                                  f"ramp rate {ramp_c_per_min} °C/min > the map's {limit} °C/min")
        field = self.regmap.ramp_c_per_min
        try:
            held = field.decode(field.encode(ramp_c_per_min))
        except (ValueError, OverflowError):
            held = ramp_c_per_min  # write_field names the unrepresentable value
        # A register of whole °C/min would run 1.5 as 2 and 0.4 as 0 (no limit at all on an
        # F4T): refuse what the controller would not do rather than ramp at another rate.
        if abs(held - ramp_c_per_min) > RAMP_WRITE_TOLERANCE * ramp_c_per_min:
            raise ValueOutOfRange(
                self.link.device,
                f"ramp rate {ramp_c_per_min:g} °C/min cannot be written to register "
                f"{field.address}: it would hold {held:g} °C/min (the map's scale "
                f"{field.scale:g}); choose a rate the register can hold")
        await self._setup()
        await self.link.write_field(field, ramp_c_per_min, idempotent=True)

    async def run(self) -> None:
        if self.regmap.run is not None:
            await self.link.write_field(self.regmap.run, self.regmap.run_on, idempotent=True)

    async def stop(self) -> None:
        if self.regmap.run is not None:
            await self.link.write_field(self.regmap.run, self.regmap.run_off, idempotent=True)

    async def close(self) -> None:
        """Release the connection (the controller keeps running its last command)."""
        await self.link.close()

    async def _setup(self) -> None:
        """The map's one-time writes (e.g. the F4T's ramp action and scale), once per driver."""
        if self._setup_done:
            return
        for f, value in self.regmap.setup:
            await self.link.write_field(f, value, idempotent=True)
        self._setup_done = True
