"""Register maps as data: one table per controller model, no per-model code paths.

A :class:`Field` says where a quantity lives and how it is encoded; the
drivers (``drivers.chamber``, ``drivers.turntable``) and the simulators' Modbus
servers read the same tables, so a map is written once. See docs/registers.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from drivers import codec

Encoding = Literal["int16", "uint16", "float32"]


@dataclass(frozen=True)
class Field:
    """One quantity in the holding-register space (0-based protocol addresses)."""

    address: int
    encoding: Encoding = "int16"
    scale: float = 1.0  # counts per engineering unit (int16/uint16 only)
    word_order: codec.WordOrder = "high_first"  # float32 only

    @property
    def n_registers(self) -> int:
        return 2 if self.encoding == "float32" else 1

    def decode(self, words: list[int] | tuple[int, ...]) -> float:
        if self.encoding == "float32":
            return codec.decode_float32(words, self.word_order)
        return codec.decode_scaled(words[0], self.scale, signed=self.encoding == "int16")

    def encode(self, value: float) -> list[int]:
        """Raises ValueError when the value cannot be represented (the driver maps it)."""
        if self.encoding == "float32":
            return codec.encode_float32(value, self.word_order)
        return [codec.encode_scaled(value, self.scale, signed=self.encoding == "int16")]


@dataclass(frozen=True)
class ChamberMap:
    """Where a chamber controller keeps PV, SP, WSP, ramp rate, run/stop and alarms."""

    name: str
    process_c: Field
    setpoint_c: Field
    working_setpoint_c: Field
    ramp_c_per_min: Field
    run: Field  # 1 = run, 0 = stop
    alarms: Field  # bit field, names in ``alarm_bits``
    alarm_bits: dict[int, str] = field(default_factory=dict)
    range_c: tuple[float, float] = (-70.0, 180.0)
    # Largest run of undefined registers one read may span (0: read field by field).
    block_read_max_gap: int = 0

    def fields(self) -> list[Field]:
        return [self.process_c, self.setpoint_c, self.working_setpoint_c, self.ramp_c_per_min,
                self.run, self.alarms]


@dataclass(frozen=True)
class TurntableMap:
    """A positioner with up to three axes; per-axis fields are at ``base + axis * stride``."""

    name: str
    n_axes: int
    position_deg: Field  # axis 0 (outer); readback
    target_deg: Field  # axis 0 (outer); written by move commands
    axis_stride: int
    command: Field  # write COMMAND_MOVE / COMMAND_STOP
    status: Field  # bit field, see STATUS_* below
    faults: Field  # bit field, names in ``fault_bits``
    fault_bits: dict[int, str] = field(default_factory=dict)
    block_read_max_gap: int = 8

    def axis_field(self, base: Field, axis: int) -> Field:
        return Field(base.address + axis * self.axis_stride, base.encoding, base.scale,
                     base.word_order)


# --- chamber controllers ---------------------------------------------------

#: Eurotherm 3216 style: one decimal place (×10) signed integers, low addresses.
EUROTHERM_3216 = ChamberMap(
    name="eurotherm3216",
    process_c=Field(1, "int16", 10.0),
    setpoint_c=Field(2, "int16", 10.0),
    working_setpoint_c=Field(5, "int16", 10.0),
    ramp_c_per_min=Field(35, "uint16", 10.0),  # SP rate limit, °C/min × 10
    run=Field(57, "uint16"),
    alarms=Field(74, "uint16"),
    alarm_bits={0: "deviation_high", 1: "deviation_low", 2: "sensor_break"},
    range_c=(-70.0, 180.0),
    block_read_max_gap=40,  # parameters 1…80 are all defined on the 3216
)

#: Watlow F4T style: IEEE-754 floats, low word first, at 4-digit addresses.
WATLOW_F4T = ChamberMap(
    name="watlow_f4t",
    process_c=Field(2820, "float32", word_order="low_first"),
    setpoint_c=Field(2782, "float32", word_order="low_first"),
    working_setpoint_c=Field(2800, "float32", word_order="low_first"),
    ramp_c_per_min=Field(2810, "float32", word_order="low_first"),
    run=Field(2830, "uint16"),
    alarms=Field(2840, "uint16"),
    alarm_bits={0: "deviation_high", 1: "deviation_low", 2: "sensor_break"},
    range_c=(-70.0, 180.0),
    block_read_max_gap=20,
)

CHAMBER_MAPS: dict[str, ChamberMap] = {m.name: m for m in (EUROTHERM_3216, WATLOW_F4T)}

# --- turntable --------------------------------------------------------------

COMMAND_STOP = 0
COMMAND_MOVE = 1
STATUS_IN_POSITION = 1 << 0
STATUS_MOVING = 1 << 1

#: soakcal positioner map (documented in docs/registers.md): float32, high word first.
SOAKCAL_TABLE = TurntableMap(
    name="soakcal_table",
    n_axes=3,
    position_deg=Field(100, "float32", word_order="high_first"),  # 100…105
    target_deg=Field(200, "float32", word_order="high_first"),  # 200…205
    axis_stride=2,
    command=Field(210, "uint16"),
    status=Field(106, "uint16"),  # right after the positions: one read per poll
    faults=Field(107, "uint16"),
    fault_bits={0: "following_error", 1: "encoder_error", 2: "limit_switch"},
)

TURNTABLE_MAPS: dict[str, TurntableMap] = {SOAKCAL_TABLE.name: SOAKCAL_TABLE}


def bits_to_names(word: int, names: dict[int, str]) -> tuple[str, ...]:
    """Decode a bit-field register into the names of the set bits (unknown bits as ``bitN``)."""
    return tuple(names.get(b, f"bit{b}") for b in range(16) if word >> b & 1)
