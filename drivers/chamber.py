"""Chamber controller driver: :class:`drivers.protocols.Chamber` over a :class:`ChamberMap`."""

from __future__ import annotations

import math

from drivers.chamber_park import park_chamber
from drivers.faults import ValueOutOfRange
from drivers.modbus_link import ModbusLink
from drivers.protocols import ChamberStatus
from drivers.ramp_rule import RampControl, map_ramp_control, ramp_refusal
from drivers.registermaps import ChamberMap, SequenceStep, bits_to_names

# Largest relative difference between the ramp rate asked for and the one the register holds.
RAMP_WRITE_TOLERANCE = 0.05


class ModbusChamber:
    """Any chamber controller whose registers a :class:`ChamberMap` describes.

    Every write sets a level (setpoint, ramp rate, run/stop, setup values), so each is
    idempotent and the link may repeat it after a lost reply (drivers/modbus_link.py).
    """

    def __init__(self, link: ModbusLink, regmap: ChamberMap, *,
                 max_rate_c_per_min: float | None = None) -> None:
        self.link = link
        self.regmap = regmap
        # The rig's chamber.max_rate_c_per_min (the chamber's own fastest rate), else the
        # map's limits.max_ramp_c_per_min: what a controller without a ramp steps at.
        self.ramp_control: RampControl = map_ramp_control(regmap, max_rate_c_per_min)
        self._setup_done = False
        # The last rate written through a [[sequence.set_ramp_rate]] when the controller has
        # no ramp register to read back (NaN before the first write).
        self._ramp_written = math.nan

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
        roles = m.status_roles()
        values = await self.link.read_fields([f for _, f in roles], m.block_read_max_gap)
        got = {name: v for (name, _), v in zip(roles, values, strict=True)}
        # A map without a run register describes a controller that controls whenever powered.
        running = True
        if m.run is not None:
            running = int(got["run"]) == m.run_on
        if m.ramp_c_per_min is not None:
            ramp = got["ramp_c_per_min"]
        else:  # no static ramp register: it steps, or ramps as its sequence was last told
            ramp = self._ramp_written if "set_ramp_rate" in m.sequences else 0.0
        alarms: tuple[str, ...] = ()
        if m.alarms is not None:
            word = int(got["alarms"])
            # Only the bits the map names as alarms count; informative bits are not faults.
            mask = sum(1 << b for b in m.alarm_bits) if m.alarm_bits else 0xFFFF
            alarms = bits_to_names(word & mask & ~sum(1 << b for b in m.info_bits),
                                   m.alarm_bits)
        for state in m.alarm_states:  # enumerated alarm registers, read one by one
            active = state.alarm(await self.link.read_field(state.field))
            if active is not None:
                alarms += (active,)
        return ChamberStatus(
            process_c=got["process_c"],
            setpoint_c=got["setpoint_c"],
            working_setpoint_c=got.get("working_setpoint_c"),
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
        steps = self.regmap.sequences.get("set_setpoint")
        if steps:
            await self._write_sequence(steps, setpoint_c)
            return
        await self.link.write_field(self.regmap.setpoint_c, setpoint_c, idempotent=True)

    async def set_ramp_rate(self, ramp_c_per_min: float) -> None:
        """Write the ramp rate; 0 means step (one rule for every chamber:
        :mod:`drivers.ramp_rule`). A controller without a ramp gets nothing written."""
        if ramp_c_per_min < 0:
            raise ValueOutOfRange(self.link.device, f"ramp rate {ramp_c_per_min} °C/min < 0")
        refused = ramp_refusal(self.ramp_control, ramp_c_per_min)
        if refused is not None:
            raise ValueOutOfRange(self.link.device, refused)
        field = self.regmap.ramp_field()
        if field is None:
            return  # it steps at the chamber's own rate: nothing to write
        limit = self.regmap.max_ramp_c_per_min
        if limit is not None and ramp_c_per_min > limit:
            raise ValueOutOfRange(self.link.device,
                                  f"ramp rate {ramp_c_per_min} °C/min > the map's {limit} °C/min")
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
        steps = self.regmap.sequences.get("set_ramp_rate")
        if steps:
            await self._write_sequence(steps, ramp_c_per_min)
            self._ramp_written = ramp_c_per_min
            return
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

    async def _write_sequence(self, steps: tuple[SequenceStep, ...], commanded: float) -> None:
        """The map's ordered writes; a failure stops the sequence where it failed (the
        fault names the register), later steps are not sent.

        Each step writes a level (a value into a register: end the profile, the setpoint),
        so writing it again after a lost reply leaves the controller as one write would:
        the link may repeat it (idempotent)."""
        for step in steps:
            await self.link.write_field(step.field, step.word_value(commanded), idempotent=True)

    async def _setup(self) -> None:
        """The map's one-time writes (e.g. the F4T's ramp action and scale), once per driver."""
        if self._setup_done:
            return
        for f, value in self.regmap.setup:
            await self.link.write_field(f, value, idempotent=True)
        self._setup_done = True

    async def park(self, setpoint_c: float | None = None) -> str:
        """The chamber's safe state (:meth:`drivers.protocols.Chamber.park`): the setpoint
        to ``setpoint_c`` or the map's ``[safe] setpoint_c``, then, where the map says
        ``[safe] stop = true``, the controller stopped. A target beyond the chamber's
        range goes to the range's edge (the park must not be refused) and the report
        says so."""
        return await park_chamber(self, setpoint_c, stopped="controller stopped")
