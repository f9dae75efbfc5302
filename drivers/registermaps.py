"""Register maps as data: TOML files, loaded and validated here, no per-model code paths.

A lab adds a controller by writing a map file (format: docs/registers.md),
never Python. The shipped files live in ``drivers/maps/``; a rig config names
one (``map = "eurotherm-3216"``) or gives a path. The drivers
(``drivers.chamber``, ``drivers.turntable``) and the twin's Modbus servers
(``simulators.chamber_sim``, ``simulators.turntable_sim``) read the same
:class:`ChamberMap` / :class:`TurntableMap`, so a map is written once.

TOML through the standard library's ``tomllib``: no dependency, comments for
the citations every register carries, and its parser already refuses a key
written twice (a duplicated register) with line and column.
"""

from __future__ import annotations

import math
import struct
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from calibration.thermal_plant import AMBIENT_C
from drivers import codec

Encoding = Literal["int16", "uint16", "int32", "float32", "bit"]
ENCODINGS: tuple[str, ...] = ("int16", "uint16", "int32", "float32", "bit")
#: The four Modbus data tables: holding registers (FC 3/6/16), input registers (FC 4),
#: coils (FC 1/5) and discrete inputs (FC 2). Bits (coils, discrete inputs) are type "bit".
Table = Literal["holding", "input", "coil", "discrete"]
TABLES: tuple[str, ...] = ("holding", "input", "coil", "discrete")
READ_ONLY_TABLES = ("input", "discrete")
BIT_TABLES = ("coil", "discrete")
ACCESS = ("r", "w", "rw")
WORD_ORDERS = ("high_first", "low_first")
#: One Modbus read returns at most 125 registers: a larger gap cannot be spanned.
MAX_READ_REGISTERS = 125
SCHEMA = "soakcal-register-map/1"
MAPS_DIR = Path(__file__).with_name("maps")

#: Names the drivers give meaning to; any other register name is free (identity, setup, ...).
CHAMBER_REQUIRED = ("process_c", "setpoint_c")
#: Roles a chamber map must define unless it lists them under ``absent_roles`` (a
#: controller without a working setpoint, e.g. CSZ EZT-430i, or without a static ramp,
#: e.g. a Watlow F4): an omission by mistake is refused, a documented absence is not.
CHAMBER_ABSENT_OK = ("working_setpoint_c", "ramp_c_per_min")
CHAMBER_OPTIONAL = ("alarms",)
#: Write sequences a chamber map may declare (``[[sequence.NAME]]``): ordered writes made
#: instead of the single write of the quantity, and the quantity each must carry.
SEQUENCES = {"set_setpoint": "setpoint_c", "set_ramp_rate": "ramp_c_per_min"}
SEQUENCE_STEP_KEYS = {"register", "value", "from", "note"}
TABLE_REQUIRED = ("target_deg", "status")
TABLE_OPTIONAL = ("faults",)
#: Roles a turntable map may list under ``absent_roles``: a drive whose position readback
#: register is not documented (the driver then reports the commanded angles, and says so).
TABLE_ABSENT_OK = ("position_deg",)
#: Turntable write sequences (``[[sequence.NAME]]``), made per axis on that axis' unit id:
#: ``move`` replaces the target write + ``[command] move`` (one step carries the target,
#: ``from = "target_deg"``, the last is usually the trigger); ``home`` starts homing and
#: ``stop`` halts (constants only).
TABLE_SEQUENCES = {"move": "target_deg", "home": None, "stop": None}

#: Keys a map file may use; anything else is a typo and refused with its key.
TOP_KEYS = {"schema", "kind", "name", "title", "undocumented", "source", "defaults", "limits",
            "safe", "identity", "run", "setup", "registers", "axes", "command", "checks",
            "alarm_states", "absent_roles", "sequence"}
CHECK_KEYS = {"register", "expect", "one_of", "min", "max", "what", "fix"}
REGISTER_KEYS = {"address", "protocol_address", "table", "type", "scale", "offset",
                 "word_order", "access", "write", "unit", "source", "note", "bits", "info_bits",
                 "states", "ok"}
SECTION_KEYS = {
    "defaults": {"word_order", "unit_id"},
    "limits": {"range_c", "max_ramp_c_per_min", "range_deg", "block_read_max_gap"},
    "safe": {"setpoint_c", "angles_deg", "stop"},
    "identity": {"register", "expect"},
    "run": {"register", "on", "off"},
    "axes": {"count", "stride", "unit_ids"},
    "command": {"move", "stop"},
}

#: Older rig configs and scripts name the maps like this; they mean the shipped files.
ALIASES = {"eurotherm3216": "eurotherm-3216", "watlow_f4t": "watlow-f4t",
           "soakcal_table": "soakcal-table"}


class MapError(ValueError):
    """A map file the drivers cannot use; the message names the file and the key."""


@dataclass(frozen=True)
class Field:
    """One quantity in the holding-register space (0-based protocol addresses).

    Engineering value = register value / ``scale`` + ``offset``: a °F controller is
    mapped to °C with ``scale = 1.8`` (× counts per degree) and ``offset = -17.7778``.
    """

    address: int
    encoding: Encoding = "int16"
    scale: float = 1.0  # counts per engineering unit
    word_order: codec.WordOrder = "high_first"  # 32-bit encodings only
    access: str = "rw"
    offset: float = 0.0  # engineering units added after the scale
    table: Table = "holding"
    single_write: bool = False  # FC 6 (one register) instead of FC 16; coils are always FC 5

    @property
    def n_registers(self) -> int:
        return 2 if self.encoding in ("int32", "float32") else 1

    def decode(self, words: list[int] | tuple[int, ...]) -> float:
        return self.decode_raw(words) / self.scale + self.offset

    def decode_raw(self, words: list[int] | tuple[int, ...]) -> float:
        """The register value before scale and offset (counts, or the float as sent)."""
        if self.encoding == "float32":
            return codec.decode_float32(words, self.word_order)
        if self.encoding == "int32":
            hi, lo = (words[0], words[1]) if self.word_order == "high_first" else (
                words[1], words[0])
            return float(struct.unpack(">i", struct.pack(">HH", hi & 0xFFFF, lo & 0xFFFF))[0])
        if self.encoding == "bit":
            return float(words[0] & 1)
        return codec.decode_scaled(words[0], 1.0, signed=self.encoding == "int16")

    def encode(self, value: float) -> list[int]:
        """Raises ValueError when the value cannot be represented (the driver maps it)."""
        raw = (value - self.offset) * self.scale
        if self.encoding == "float32":
            return codec.encode_float32(raw, self.word_order)
        if self.encoding == "int32":
            counts = int(round(raw))
            if not -(2**31) <= counts < 2**31:
                raise ValueError(f"{value} × {self.scale} does not fit a signed 32-bit value")
            hi, lo = struct.unpack(">HH", struct.pack(">i", counts))
            return [hi, lo] if self.word_order == "high_first" else [lo, hi]
        if self.encoding == "bit":
            if raw not in (0.0, 1.0):
                raise ValueError(f"{value} is not a bit (0 or 1)")
            return [int(raw)]
        return [codec.encode_scaled(raw, 1.0, signed=self.encoding == "int16")]


@dataclass(frozen=True)
class Identity:
    """A register whose value names the model (e.g. the F4T's Hardware ID, 124)."""

    register: str
    field: Field
    expect: float


@dataclass(frozen=True)
class RegisterCheck:
    """A register ``rig check`` reads and compares (e.g. the F4T's display units = °C).

    The register passes when it reads ``expect`` exactly, or (when given) any of
    ``one_of``, or a value within ``lo``…``hi``; ``expect`` is then the value a
    well-set-up device reads (what the twin serves).
    """

    register: str
    field: Field
    expect: float
    what: str  # what a pass means, e.g. "temperature units are °C"
    fix: str = ""
    one_of: tuple[float, ...] = ()
    lo: float | None = None
    hi: float | None = None

    def accepts(self, value: float) -> bool:
        if self.one_of:
            return value in self.one_of
        if self.lo is not None or self.hi is not None:
            return ((self.lo is None or value >= self.lo)
                    and (self.hi is None or value <= self.hi))
        return value == self.expect

    def wanted(self) -> str:
        """What the check accepts, as a person reads it: 15, one of 15, 16, or 0…10."""
        def num(v: float) -> str:
            return str(int(v)) if v == int(v) else f"{v:g}"

        if self.one_of:
            return "one of " + ", ".join(num(v) for v in self.one_of)
        if self.lo is not None or self.hi is not None:
            lo = "" if self.lo is None else num(self.lo)
            hi = "" if self.hi is None else num(self.hi)
            return f"{lo}…{hi}"
        return num(self.expect)


@dataclass(frozen=True)
class StateAlarm:
    """A register whose values are named states (e.g. one alarm's state on a Watlow F4T):
    any value outside ``ok`` is an active alarm, reported by its state's name."""

    register: str
    field: Field
    states: dict[int, str]
    ok: frozenset[int]

    def alarm(self, value: float) -> str | None:
        """``None`` in an ok state; else ``"register: state"``."""
        v = int(value)
        if v in self.ok:
            return None
        return f"{self.register}: {self.states.get(v, f'state {v}')}"


@dataclass(frozen=True)
class SequenceStep:
    """One write of a ``[[sequence.NAME]]``: a constant (``value``) or the commanded
    quantity (``source``, e.g. ``"setpoint_c"``) into ``register``."""

    register: str
    field: Field
    value: float | None = None
    source: str | None = None  # "setpoint_c" or "ramp_c_per_min": the value being set

    def word_value(self, commanded: float) -> float:
        return commanded if self.source is not None else float(self.value or 0.0)


@dataclass(frozen=True)
class ChamberMap:
    """Where a chamber controller keeps PV, SP, WSP, ramp rate, run/stop and alarms."""

    name: str
    process_c: Field
    setpoint_c: Field
    # None: the controller has no such register (the map lists it under ``absent_roles``).
    working_setpoint_c: Field | None
    ramp_c_per_min: Field | None
    run: Field | None = None  # None: the controller controls whenever powered
    alarms: Field | None = None  # bit field, names in ``alarm_bits``
    alarm_states: tuple[StateAlarm, ...] = ()  # enumerated alarm registers
    alarm_bits: dict[int, str] = field(default_factory=dict)
    info_bits: dict[int, str] = field(default_factory=dict)  # reported, not alarms
    run_on: int = 1
    run_off: int = 0
    identity: Identity | None = None
    # Written once before the first ramp-rate write (e.g. the F4T's ramp action and scale).
    setup: tuple[tuple[Field, float], ...] = ()
    checks: tuple[RegisterCheck, ...] = ()
    registers: dict[str, Field] = field(default_factory=dict)  # every named register
    range_c: tuple[float, float] = (-70.0, 180.0)
    max_ramp_c_per_min: float | None = None
    safe_setpoint_c: float = AMBIENT_C
    # [safe] stop = true: the park also stops the controller (its run register), after the
    # safe setpoint is written; false (the default) leaves it controlling at that setpoint.
    safe_stop: bool = False
    # Largest run of undefined registers one read may span (0: read field by field).
    block_read_max_gap: int = 0
    title: str = ""
    source: str = ""  # the file the map came from
    undocumented: tuple[str, ...] = ()
    unit_id: int = 1  # the device's Modbus unit id unless the rig config gives device_id
    # ``[[sequence.set_setpoint]]`` / ``[[sequence.set_ramp_rate]]``: ordered writes made
    # instead of the one write of the quantity (e.g. a Watlow F4's profile terminate first).
    sequences: dict[str, tuple[SequenceStep, ...]] = field(default_factory=dict)

    def status_roles(self) -> list[tuple[str, Field]]:
        """(role, field) of one status read, in read order; absent roles left out."""
        roles = [("process_c", self.process_c), ("setpoint_c", self.setpoint_c),
                 ("working_setpoint_c", self.working_setpoint_c),
                 ("ramp_c_per_min", self.ramp_c_per_min), ("run", self.run),
                 ("alarms", self.alarms)]
        return [(name, f) for name, f in roles if f is not None]

    def fields(self) -> list[Field]:
        """The fields one status read covers (optional ones only when mapped)."""
        return [f for _, f in self.status_roles()]

    def ramp_field(self) -> Field | None:
        """The register a ramp rate is written to: the role's, else the sequence step's."""
        if self.ramp_c_per_min is not None:
            return self.ramp_c_per_min
        return next((s.field for s in self.sequences.get("set_ramp_rate", ())
                     if s.source is not None), None)


@dataclass(frozen=True)
class TurntableMap:
    """A positioner with up to three axes; per-axis fields are at ``base + axis * stride``."""

    name: str
    n_axes: int
    # axis 0 (outer); readback. None: the map lists it under ``absent_roles`` (no documented
    # position register): the driver reports the commanded angles once in position.
    position_deg: Field | None
    target_deg: Field  # axis 0 (outer); written by move commands
    axis_stride: int
    # write ``move_value`` / ``stop_value``; None when ``[[sequence.move]]`` moves the table
    command: Field | None
    status: Field  # bit field: ``in_position_bit``, ``moving_bit`` (and ``homed_bit``)
    faults: Field | None = None  # bit field, names in ``fault_bits``
    fault_bits: dict[int, str] = field(default_factory=dict)
    block_read_max_gap: int = 8
    move_value: int = 1
    stop_value: int = 0
    in_position_bit: int = 0
    moving_bit: int | None = 1  # None: the drive has no "moving" bit (moving = not in position)
    homed_bit: int | None = None  # the homing-done bit ("homed"), None if the map has none
    # Every named status bit. Those whose name starts with "fault" (a drive's status word
    # carrying its fault flag) are reported as faults, like the ``faults`` register's bits.
    status_bits: dict[int, str] = field(default_factory=dict)
    identity: Identity | None = None
    checks: tuple[RegisterCheck, ...] = ()
    registers: dict[str, Field] = field(default_factory=dict)
    range_deg: float = 720.0  # |target| the table accepts
    safe_angles_deg: tuple[float, ...] = ()
    title: str = ""
    source: str = ""
    undocumented: tuple[str, ...] = ()
    unit_id: int = 1
    # ``[axes] unit_ids``: one Modbus unit id per axis (a drive per axis on one bus), outer
    # first; empty: every axis answers the one unit id (``unit_id`` or the rig's device_id).
    unit_ids: tuple[int, ...] = ()
    # ``[[sequence.move]]`` / ``home`` / ``stop``: ordered writes per axis (see SEQUENCES).
    sequences: dict[str, tuple[SequenceStep, ...]] = field(default_factory=dict)

    def axis_field(self, base: Field, axis: int) -> Field:
        return replace(base, address=base.address + axis * self.axis_stride)

    def axis_unit(self, axis: int, default: int) -> int:
        """The unit id axis ``axis`` answers: its ``unit_ids`` entry, else ``default``."""
        return self.unit_ids[axis] if self.unit_ids else default


# --- loading ------------------------------------------------------------------


def shipped_maps() -> dict[str, Path]:
    """Name → file of every map shipped in ``drivers/maps/``."""
    return {p.stem: p for p in sorted(MAPS_DIR.glob("*.toml"))}


def resolve_map(ref: str) -> Path:
    """A shipped map name (or an old alias) or a path to a ``.toml`` file → its path."""
    name = ALIASES.get(ref, ref)
    shipped = shipped_maps()
    if name in shipped:
        return shipped[name]
    path = Path(ref).expanduser()
    if path.suffix == ".toml" or "/" in ref:
        if not path.is_file():
            raise MapError(f"{ref}: no such map file")
        return path
    raise MapError(f"map {ref!r}: not a shipped map ({', '.join(shipped)}) nor a .toml path")


def load_map(ref: str | Path) -> ChamberMap | TurntableMap:
    """Load and validate a map file; every problem is a :class:`MapError` naming file and key."""
    path = ref if isinstance(ref, Path) else resolve_map(ref)
    try:
        with path.open("rb") as fh:
            doc = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        # tomllib reports a key written twice (a duplicated register) with line and column.
        raise MapError(f"{path}: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise MapError(f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02X} at offset "
                       f"{exc.start}): save the map file as UTF-8") from exc
    except OSError as exc:
        raise MapError(f"{path}: cannot read ({exc.strerror})") from exc
    return _MapReader(path, doc).build()


def load_chamber_map(ref: str | Path) -> ChamberMap:
    m = load_map(ref)
    if not isinstance(m, ChamberMap):
        raise MapError(f"{ref}: kind: expected \"chamber\", the file describes a turntable")
    return m


def load_turntable_map(ref: str | Path) -> TurntableMap:
    m = load_map(ref)
    if not isinstance(m, TurntableMap):
        raise MapError(f"{ref}: kind: expected \"turntable\", the file describes a chamber")
    return m


class _MapReader:
    """Turns one parsed TOML document into a map, collecting errors with their keys."""

    def __init__(self, path: Path, doc: dict[str, Any]) -> None:
        self.path = path
        self.doc = doc

    def fail(self, key: str, problem: str) -> MapError:
        return MapError(f"{self.path}: {key}: {problem}")

    def build(self) -> ChamberMap | TurntableMap:
        d = self.doc
        if d.get("schema") != SCHEMA:
            raise self.fail("schema", f"expected \"{SCHEMA}\", got {d.get('schema')!r}")
        for key in d:
            if key not in TOP_KEYS:
                raise self.fail(key, f"unknown key (expected one of {', '.join(sorted(TOP_KEYS))})")
        for section, allowed in SECTION_KEYS.items():
            value = d.get(section, {})
            if not isinstance(value, dict):
                raise self.fail(section, "expected a table")
            for key in value:
                if key not in allowed:
                    raise self.fail(f"{section}.{key}", "unknown key (expected one of "
                                    f"{', '.join(sorted(allowed))})")
        kind = d.get("kind")
        if kind not in ("chamber", "turntable"):
            raise self.fail("kind", f"expected \"chamber\" or \"turntable\", got {kind!r}")
        name = d.get("name")
        if not isinstance(name, str) or not name:
            raise self.fail("name", "expected a non-empty string")
        regs = self.registers()
        if kind == "chamber":
            return self.chamber(name, regs)
        return self.turntable(name, regs)

    # --- registers -------------------------------------------------------------
    def registers(self) -> dict[str, Field]:
        table = self.doc.get("registers")
        if not isinstance(table, dict) or not table:
            raise self.fail("registers", "expected a table of named registers")
        default_order = self.doc.get("defaults", {}).get("word_order", "high_first")
        if default_order not in WORD_ORDERS:
            raise self.fail("defaults.word_order", f"expected \"high_first\" or "
                            f"\"low_first\", got {default_order!r}")
        fields: dict[str, Field] = {}
        for reg, spec in table.items():
            fields[reg] = self.register(reg, spec, default_order)
        self.check_overlaps(fields)
        return fields

    def register(self, reg: str, spec: Any, default_order: str) -> Field:
        key = f"registers.{reg}"
        if not isinstance(spec, dict):
            raise self.fail(key, "expected a table (address, type, ...)")
        for extra in spec:
            if extra not in REGISTER_KEYS:
                raise self.fail(f"{key}.{extra}", "unknown key (expected one of "
                                f"{', '.join(sorted(REGISTER_KEYS))})")
        address = spec.get("address")
        if not isinstance(address, int) or isinstance(address, bool) or not 0 <= address <= 65535:
            raise self.fail(f"{key}.address", f"expected a protocol address 0…65535, got "
                            f"{address!r}")
        if 40001 <= address <= 49999 and spec.get("protocol_address") is not True:
            raise self.fail(f"{key}.address",
                            f"{address} looks like a 4xxxx holding-register reference (the "
                            f"\"4\" names the table, counting from 1): write the protocol "
                            f"address, address = {address - 40001}; if the manual really "
                            f"gives protocol address {address}, add protocol_address = true")
        enc = spec.get("type")
        if enc not in ENCODINGS:
            raise self.fail(f"{key}.type", f"unknown type {enc!r} (expected one of "
                            f"{', '.join(ENCODINGS)})")
        table = spec.get("table", "holding")
        if table not in TABLES:
            raise self.fail(f"{key}.table", f"expected one of {', '.join(TABLES)}, got {table!r}")
        if (table in BIT_TABLES) != (enc == "bit"):
            raise self.fail(f"{key}.type", f"a {table} register is "
                            + ("type \"bit\"" if table in BIT_TABLES else
                               f"a 16/32-bit type, not {enc!r}"))
        width = 2 if enc in ("int32", "float32") else 1
        if address + width - 1 > 65535:
            raise self.fail(f"{key}.address", f"a {enc} at {address} needs registers "
                            f"{address}…{address + width - 1}, past the last one (65535)")
        scale = spec.get("scale", 1)
        if not isinstance(scale, int | float) or isinstance(scale, bool) or not scale > 0 \
                or not math.isfinite(scale):
            raise self.fail(f"{key}.scale", f"expected counts per unit > 0, got {scale!r}")
        offset = self.number(f"{key}.offset", spec.get("offset"), 0.0)
        order = spec.get("word_order", default_order)
        if order not in WORD_ORDERS:
            raise self.fail(f"{key}.word_order",
                            f"expected \"high_first\" or \"low_first\", got {order!r}")
        access = spec.get("access", "r")
        if access not in ACCESS:
            raise self.fail(f"{key}.access", f"expected one of {', '.join(ACCESS)}, got "
                            f"{access!r}")
        if table in READ_ONLY_TABLES and access != "r":
            raise self.fail(f"{key}.access", f"{table} registers are read-only in Modbus: "
                            "expected \"r\"")
        write = spec.get("write", "multiple")
        if write not in ("multiple", "single"):
            raise self.fail(f"{key}.write", f"expected \"multiple\" (FC 16) or \"single\" "
                            f"(FC 6), got {write!r}")
        if write == "single" and (width != 1 or table != "holding"):
            raise self.fail(f"{key}.write", "a single-register write (FC 6) carries one "
                            "holding register")
        if not isinstance(spec.get("source", ""), str):
            raise self.fail(f"{key}.source", "expected the citation as a string")
        return Field(address, enc, float(scale), order, access,  # type: ignore[arg-type]
                     float(offset or 0.0), table, write == "single")

    def check_overlaps(self, fields: dict[str, Field]) -> None:
        """Two names on one register is a duplicated register too (a copy-paste slip)."""
        owner: dict[tuple[str, int], str] = {}
        for reg, f in fields.items():
            for a in range(f.address, f.address + f.n_registers):
                if (f.table, a) in owner:
                    raise self.fail(f"registers.{reg}.address",
                                    f"register {a} is also registers.{owner[f.table, a]}")
                owner[f.table, a] = reg

    def require(self, regs: dict[str, Field], names: tuple[str, ...], kind: str) -> None:
        for reg in names:
            if reg not in regs:
                raise self.fail(f"registers.{reg}", f"missing (required in a {kind} map)")

    def writable(self, regs: dict[str, Field], names: tuple[str, ...]) -> None:
        """Registers the driver writes must say so: a read-only one is a wrong map."""
        for reg in names:
            if "w" not in regs[reg].access:
                raise self.fail(f"registers.{reg}.access",
                                f"the driver writes this register: expected \"rw\" or \"w\", "
                                f"got {regs[reg].access!r}")

    def bit_word(self, regs: dict[str, Field], names: tuple[str, ...]) -> None:
        for reg in names:
            if reg in regs and (regs[reg].encoding not in ("uint16", "int16")
                                or regs[reg].table in BIT_TABLES):
                raise self.fail(f"registers.{reg}.type",
                                f"a bit word is one 16-bit register, got {regs[reg].encoding!r}")

    def ref(self, regs: dict[str, Field], key: str, reg: Any) -> Field:
        if not isinstance(reg, str) or reg not in regs:
            raise self.fail(key, f"names no register in [registers] ({reg!r})")
        return regs[reg]

    def bits(self, key: str, table: Any) -> dict[int, str]:
        if table is None:
            return {}
        if not isinstance(table, dict):
            raise self.fail(key, "expected a table bit number = \"name\"")
        out: dict[int, str] = {}
        for bit, label in table.items():
            if not str(bit).isdigit() or not 0 <= int(bit) <= 15 or not isinstance(label, str):
                raise self.fail(f"{key}.{bit}", "expected bit 0…15 = \"name\"")
            out[int(bit)] = label
        return out

    def state_alarms(self, regs: dict[str, Field]) -> tuple[StateAlarm, ...]:
        """``alarm_states = ["alarm_1", ...]``: registers with ``states`` and ``ok``."""
        names = self.doc.get("alarm_states", [])
        if not isinstance(names, list):
            raise self.fail("alarm_states", "expected a list of register names")
        out = []
        for i, reg in enumerate(names):
            f = self.ref(regs, f"alarm_states[{i}]", reg)
            spec = self.doc["registers"][reg]
            key = f"registers.{reg}"
            if f.encoding not in ("uint16", "int16"):
                raise self.fail(f"{key}.type", "a state register is one 16-bit register")
            states = spec.get("states")
            if not isinstance(states, dict) or not states:
                raise self.fail(f"{key}.states", "expected a table value = \"name\"")
            named: dict[int, str] = {}
            for value, label in states.items():
                if not str(value).lstrip("-").isdigit() or not isinstance(label, str):
                    raise self.fail(f"{key}.states.{value}", "expected value = \"name\"")
                named[int(value)] = label
            ok = spec.get("ok")
            if not isinstance(ok, list) or not ok or not all(
                    isinstance(v, int) and v in named for v in ok):
                raise self.fail(f"{key}.ok", "expected the list of non-alarm values, each "
                                "named in states")
            out.append(StateAlarm(reg, f, named, frozenset(ok)))
        for reg, spec in self.doc["registers"].items():
            if isinstance(spec, dict) and ("states" in spec or "ok" in spec) \
                    and reg not in names:
                raise self.fail(f"registers.{reg}.states",
                                "only registers listed in alarm_states have states")
        return tuple(out)

    def identity(self, regs: dict[str, Field]) -> Identity | None:
        ident = self.doc.get("identity")
        if ident is None:
            return None
        if not isinstance(ident, dict):
            raise self.fail("identity", "expected a table (register, expect)")
        f = self.ref(regs, "identity.register", ident.get("register"))
        expect = ident.get("expect")
        if not isinstance(expect, int | float) or isinstance(expect, bool):
            raise self.fail("identity.expect", "expected the number the register reads")
        return Identity(str(ident["register"]), f, float(expect))

    def checks(self, regs: dict[str, Field]) -> tuple[RegisterCheck, ...]:
        raw = self.doc.get("checks", [])
        if not isinstance(raw, list):
            raise self.fail("checks", "expected a list of {register, expect, what, fix}")
        out = []
        for i, c in enumerate(raw):
            key = f"checks[{i}]"
            if not isinstance(c, dict):
                raise self.fail(key, "expected {register, expect, what, fix}")
            for extra in c:
                if extra not in CHECK_KEYS:
                    raise self.fail(f"{key}.{extra}", "unknown key (expected one of "
                                    f"{', '.join(sorted(CHECK_KEYS))})")
            f = self.ref(regs, f"{key}.register", c.get("register"))
            out.append(self.check(key, c, f))
        return tuple(out)

    def check(self, key: str, c: dict[str, Any], f: Field) -> RegisterCheck:
        """One ``[[checks]]`` entry: exactly one of ``expect``, ``one_of``, ``min``/``max``."""
        given = [k for k in ("expect", "one_of") if k in c] + (
            ["min/max"] if "min" in c or "max" in c else [])
        if len(given) != 1:
            raise self.fail(key, "expected exactly one of expect, one_of, min/max, got "
                            + (", ".join(given) or "none"))
        one_of: tuple[float, ...] = ()
        lo = self.number(f"{key}.min", c.get("min"), None)
        hi = self.number(f"{key}.max", c.get("max"), None)
        if "one_of" in c:
            raw = c["one_of"]
            if not isinstance(raw, list) or not raw:
                raise self.fail(f"{key}.one_of", "expected a non-empty list of values")
            one_of = tuple(self.number(f"{key}.one_of[{i}]", v, None) or 0.0
                           for i, v in enumerate(raw))
            expect = one_of[0]
        elif lo is not None or hi is not None:
            if lo is not None and hi is not None and lo > hi:
                raise self.fail(f"{key}.min", f"min {lo:g} > max {hi:g}")
            expect = lo if lo is not None else hi  # type: ignore[assignment]
        else:
            value = self.number(f"{key}.expect", c.get("expect"), None)
            assert value is not None  # a TOML value is never None
            expect = value
        what = c.get("what", f"{c['register']} = {expect:g}")
        return RegisterCheck(str(c["register"]), f, float(expect), str(what),
                             str(c.get("fix", "")), one_of, lo, hi)

    def common(self, regs: dict[str, Field]) -> dict[str, Any]:
        d = self.doc
        notes = d.get("undocumented", [])
        if not isinstance(notes, list) or not all(isinstance(n, str) for n in notes):
            raise self.fail("undocumented", "expected a list of strings")
        gap = self.gap(0)
        unit_id = d.get("defaults", {}).get("unit_id", 1)
        if not isinstance(unit_id, int) or isinstance(unit_id, bool) or not 0 <= unit_id <= 247:
            raise self.fail("defaults.unit_id", f"expected a Modbus unit id 0…247, got {unit_id!r}")
        return {"title": str(d.get("title", "")), "source": str(self.path), "unit_id": unit_id,
                "undocumented": tuple(notes), "block_read_max_gap": gap,
                "checks": self.checks(regs), "identity": self.identity(regs), "registers": regs}

    def gap(self, default: int) -> int:
        gap = self.doc.get("limits", {}).get("block_read_max_gap", default)
        if not isinstance(gap, int) or isinstance(gap, bool) or not 0 <= gap < MAX_READ_REGISTERS:
            raise self.fail("limits.block_read_max_gap",
                            f"expected an integer 0…{MAX_READ_REGISTERS - 1} (one read returns at "
                            f"most {MAX_READ_REGISTERS} registers), got {gap!r}")
        return gap

    def number(self, key: str, value: Any, default: float | None) -> float | None:
        if value is None:
            return default
        if not isinstance(value, int | float) or isinstance(value, bool) \
                or not math.isfinite(value):
            raise self.fail(key, f"expected a number, got {value!r}")
        return float(value)

    # --- kinds ---------------------------------------------------------------------
    def chamber(self, name: str, regs: dict[str, Field]) -> ChamberMap:
        self.require(regs, CHAMBER_REQUIRED, "chamber")
        absent = self.absent_roles(regs)
        self.writable(regs, ("setpoint_c",) + (("ramp_c_per_min",) if "ramp_c_per_min" in regs
                                               else ()))
        self.bit_word(regs, ("alarms",))
        d = self.doc
        limits = d.get("limits", {})
        rng = limits.get("range_c", [-70.0, 180.0])
        if not (isinstance(rng, list) and len(rng) == 2
                and all(isinstance(v, int | float) and not isinstance(v, bool)
                        and math.isfinite(v) for v in rng) and rng[0] < rng[1]):
            raise self.fail("limits.range_c", "expected [lo, hi] in °C with lo < hi")
        max_ramp = self.number("limits.max_ramp_c_per_min", limits.get("max_ramp_c_per_min"),
                               None)
        if max_ramp is not None and not max_ramp > 0:
            raise self.fail("limits.max_ramp_c_per_min",
                            f"expected the chamber's fastest ramp, > 0 °C/min, got {max_ramp:g}")
        safe = self.number("safe.setpoint_c", d.get("safe", {}).get("setpoint_c"),
                           AMBIENT_C)
        assert safe is not None
        if not rng[0] <= safe <= rng[1]:
            raise self.fail("safe.setpoint_c", f"{safe} °C outside limits.range_c {rng}")
        safe_stop = d.get("safe", {}).get("stop", False)
        if not isinstance(safe_stop, bool):
            raise self.fail("safe.stop", f"expected true or false, got {safe_stop!r}")
        if safe_stop and d.get("run") is None:
            raise self.fail("safe.stop", "stop = true needs a [run] register to stop with")
        run_field, on, off = None, 1, 0
        run = d.get("run")
        if run is not None:
            if not isinstance(run, dict):
                raise self.fail("run", "expected a table (register, on, off)")
            run_field = self.ref(regs, "run.register", run.get("register"))
            self.writable(regs, (str(run["register"]),))
            on, off = run.get("on", 1), run.get("off", 0)
            if not all(isinstance(v, int) and 0 <= v <= 0xFFFF for v in (on, off)) or on == off:
                raise self.fail("run.on", "expected two different register values 0…65535")
        alarms = regs.get("alarms")
        raw_alarms = d["registers"].get("alarms", {})
        alarm_states = self.state_alarms(regs)
        setup: list[tuple[Field, float]] = []
        for i, step in enumerate(d.get("setup", [])):
            if not isinstance(step, dict):
                raise self.fail(f"setup[{i}]", "expected {register, value}")
            f = self.ref(regs, f"setup[{i}].register", step.get("register"))
            self.writable(regs, (str(step["register"]),))
            val = self.number(f"setup[{i}].value", step.get("value"), None)
            if val is None:
                raise self.fail(f"setup[{i}].value", "missing")
            setup.append((f, val))
        return ChamberMap(
            name=name,
            process_c=regs["process_c"],
            setpoint_c=regs["setpoint_c"],
            working_setpoint_c=None if "working_setpoint_c" in absent
            else regs["working_setpoint_c"],
            ramp_c_per_min=None if "ramp_c_per_min" in absent else regs["ramp_c_per_min"],
            sequences=self.sequences(regs),
            run=run_field, run_on=on, run_off=off,
            alarms=alarms,
            alarm_states=alarm_states,
            alarm_bits=self.bits("registers.alarms.bits", raw_alarms.get("bits")),
            info_bits=self.bits("registers.alarms.info_bits", raw_alarms.get("info_bits")),
            setup=tuple(setup),
            range_c=(float(rng[0]), float(rng[1])),
            max_ramp_c_per_min=max_ramp,
            safe_setpoint_c=safe,
            safe_stop=safe_stop,
            **self.common(regs),
        )

    def absent_roles(self, regs: dict[str, Field],
                     allowed: tuple[str, ...] = CHAMBER_ABSENT_OK,
                     why_absent: str = "if the controller has no such register"
                     ) -> frozenset[str]:
        """``absent_roles = ["working_setpoint_c"]``: roles the device does not have.

        Only the ``allowed`` roles may be listed (a chamber's :data:`CHAMBER_ABSENT_OK`, a
        turntable's :data:`TABLE_ABSENT_OK`). A role neither mapped nor listed is refused
        (a forgotten register is a mistake), as is one both mapped and listed.
        """
        raw = self.doc.get("absent_roles", [])
        if not isinstance(raw, list) or not all(isinstance(r, str) for r in raw):
            raise self.fail("absent_roles", "expected a list of role names")
        for i, role in enumerate(raw):
            if role not in allowed:
                raise self.fail(f"absent_roles[{i}]", f"{role!r} cannot be absent (only "
                                f"{', '.join(allowed)} can)")
            if role in regs:
                raise self.fail(f"absent_roles[{i}]", f"{role} is listed as absent but "
                                f"[registers.{role}] maps it: keep one")
        for role in allowed:
            if role not in regs and role not in raw:
                raise self.fail(f"registers.{role}",
                                f"missing: map it, or list it in absent_roles = [\"{role}\"] "
                                f"{why_absent}")
        return frozenset(raw)

    def sequences(self, regs: dict[str, Field], allowed: dict[str, str | None] | None = None
                  ) -> dict[str, tuple[SequenceStep, ...]]:
        """``[[sequence.set_setpoint]]`` etc.: ordered writes, each checked here.

        ``allowed``: sequence name → the quantity one step must carry (``None``: constants
        only); the chamber's :data:`SEQUENCES` unless given.
        """
        allowed = SEQUENCES if allowed is None else allowed
        raw = self.doc.get("sequence", {})
        if not isinstance(raw, dict):
            raise self.fail("sequence", "expected tables [[sequence.NAME]] ...")
        out: dict[str, tuple[SequenceStep, ...]] = {}
        for name, steps in raw.items():
            key = f"sequence.{name}"
            if name not in allowed:
                raise self.fail(key, f"unknown sequence (expected one of "
                                f"{', '.join(allowed)})")
            if not isinstance(steps, list) or not steps:
                raise self.fail(key, "expected one or more [[" + key + "]] steps")
            quantity = allowed[name]
            built = []
            for i, step in enumerate(steps):
                built.append(self.sequence_step(f"{key}[{i}]", step, regs, quantity))
            carrying = [s for s in built if s.source is not None]
            if quantity is not None and len(carrying) != 1:
                raise self.fail(key, f"expected exactly one step with from = "
                                f"\"{quantity}\" (the value being set), got "
                                f"{len(carrying)}")
            out[name] = tuple(built)
        return out

    def sequence_step(self, key: str, step: Any, regs: dict[str, Field],
                      quantity: str | None) -> SequenceStep:
        if not isinstance(step, dict):
            raise self.fail(key, "expected {register, value} or {register, from}")
        if quantity is None and "from" in step:
            raise self.fail(f"{key}.from", "this sequence writes constants only (value = N)")
        for extra in step:
            if extra not in SEQUENCE_STEP_KEYS:
                raise self.fail(f"{key}.{extra}", "unknown key (expected one of "
                                f"{', '.join(sorted(SEQUENCE_STEP_KEYS))})")
        f = self.ref(regs, f"{key}.register", step.get("register"))
        self.writable(regs, (str(step["register"]),))
        if ("value" in step) == ("from" in step):
            raise self.fail(key, "expected exactly one of value (a constant) or from "
                            f"(= \"{quantity}\", the value being set)")
        if "from" in step:
            if step["from"] != quantity:
                raise self.fail(f"{key}.from", f"expected \"{quantity}\", got "
                                f"{step['from']!r}")
            return SequenceStep(str(step["register"]), f, source=quantity)
        value = self.number(f"{key}.value", step.get("value"), None)
        assert value is not None
        try:
            f.encode(value)
        except (ValueError, OverflowError) as exc:
            raise self.fail(f"{key}.value", f"{value:g} does not fit register "
                            f"{step['register']}: {exc}") from exc
        return SequenceStep(str(step["register"]), f, value=value)

    def turntable(self, name: str, regs: dict[str, Field]) -> TurntableMap:
        absent = self.absent_roles(regs, TABLE_ABSENT_OK,
                                   "if the drive's position readback is not documented")
        self.require(regs, TABLE_REQUIRED, "turntable")
        sequences = self.sequences(regs, TABLE_SEQUENCES)
        if "move" not in sequences:
            self.require(regs, ("command",), "turntable without [[sequence.move]]")
        elif "command" in self.doc:
            raise self.fail("command", "[[sequence.move]] moves the table: [command] would be "
                            "a second way (keep one)")
        self.writable(regs, ("target_deg",) + (("command",) if "move" not in sequences else ()))
        self.bit_word(regs, ("status", "faults"))
        d = self.doc
        axes = d.get("axes", {})
        n_axes = axes.get("count", 3)
        if n_axes not in (1, 2, 3):
            raise self.fail("axes.count", f"expected 1, 2 or 3, got {n_axes!r}")
        unit_ids = self.unit_ids(axes.get("unit_ids"), n_axes)
        # A drive per axis: each has the same layout, so per-axis fields share addresses.
        stride = axes.get("stride", 0 if unit_ids else 2)
        width = max(regs[r].n_registers for r in ("target_deg", "position_deg") if r in regs)
        if not isinstance(stride, int) or isinstance(stride, bool) or (
                stride < width and not (unit_ids and stride == 0)):
            raise self.fail("axes.stride", "expected registers per axis ≥ the field's width "
                            "(0 only with unit_ids: a drive per axis)")
        cmd = d.get("command", {})
        move, stop = cmd.get("move", 1), cmd.get("stop", 0)
        if not all(isinstance(v, int) and 0 <= v <= 0xFFFF for v in (move, stop)) \
                or move == stop:
            raise self.fail("command.move", "expected two different register values 0…65535")
        status = d.get("registers", {}).get("status", {})
        bits = self.bits("registers.status.bits", status.get("bits"))
        by_name = {v: k for k, v in bits.items()}
        if "in_position" not in by_name:
            raise self.fail("registers.status.bits", "missing the \"in_position\" bit")
        if "moving" not in by_name and "move" not in sequences:
            raise self.fail("registers.status.bits", "missing the \"moving\" bit")
        if "home" in sequences and "homed" not in by_name:
            raise self.fail("registers.status.bits", "[[sequence.home]] needs the homing-done "
                            "status: a \"homed\" bit")
        for reg in ("position_deg", "target_deg"):
            if reg not in regs:
                continue
            f = regs[reg]
            last = f.address + (n_axes - 1) * stride + f.n_registers - 1
            if last > 65535:
                raise self.fail(f"registers.{reg}.address",
                                f"axis {n_axes - 1} lands at {last - f.n_registers + 1} "
                                f"(address {f.address} + {n_axes - 1} × stride {stride}), past "
                                "the last register (65535)")
        limits = d.get("limits", {})
        rng = self.number("limits.range_deg", limits.get("range_deg"), 720.0)
        assert rng is not None
        if not rng > 0:
            raise self.fail("limits.range_deg", f"expected the largest |angle| > 0°, got {rng:g}")
        safe = d.get("safe", {}).get("angles_deg", [0.0] * n_axes)
        if not isinstance(safe, list) or len(safe) != n_axes:
            raise self.fail("safe.angles_deg", f"expected {n_axes} angles")
        for i, a in enumerate(safe):
            angle = self.number(f"safe.angles_deg[{i}]", a, None)
            if angle is None or abs(angle) > rng:
                raise self.fail(f"safe.angles_deg[{i}]",
                                f"{a!r}° outside limits.range_deg ±{rng:g}°")
        faults_raw = d["registers"].get("faults", {})
        common = self.common(regs)
        common["block_read_max_gap"] = self.gap(8)
        return TurntableMap(
            name=name, n_axes=n_axes,
            position_deg=None if "position_deg" in absent else regs["position_deg"],
            target_deg=regs["target_deg"],
            axis_stride=stride, command=regs.get("command") if "move" not in sequences
            else None, status=regs["status"],
            faults=regs.get("faults"),
            fault_bits=self.bits("registers.faults.bits", faults_raw.get("bits")),
            move_value=move, stop_value=stop,
            in_position_bit=by_name["in_position"], moving_bit=by_name.get("moving"),
            homed_bit=by_name.get("homed"),
            status_bits=bits,
            range_deg=float(rng),
            safe_angles_deg=tuple(float(a) for a in safe),
            unit_ids=unit_ids, sequences=sequences,
            **common,
        )

    def unit_ids(self, raw: Any, n_axes: int) -> tuple[int, ...]:
        """``[axes] unit_ids``: one distinct Modbus unit id 1…247 per axis, outer first."""
        if raw is None:
            return ()
        if not isinstance(raw, list) or len(raw) != n_axes:
            raise self.fail("axes.unit_ids", f"expected {n_axes} unit ids (one per axis)")
        for i, uid in enumerate(raw):
            if not isinstance(uid, int) or isinstance(uid, bool) or not 1 <= uid <= 247:
                raise self.fail(f"axes.unit_ids[{i}]", f"expected a Modbus unit id 1…247 "
                                f"(0 is broadcast), got {uid!r}")
        if len(set(raw)) != len(raw):
            raise self.fail("axes.unit_ids", f"{raw}: two axes on one unit id would both "
                            "answer one request")
        return tuple(raw)


def describe_map(m: ChamberMap | TurntableMap) -> str:
    """One line naming what a map describes (``soakcal rig validate``)."""
    kind = "chamber" if isinstance(m, ChamberMap) else f"turntable, {m.n_axes} axes"
    what = f"{m.name} — {m.title}" if m.title else m.name
    extra = ""
    if isinstance(m, ChamberMap):  # what the drivers will do differently, said up front
        extra += "".join(f", no {role}" for role in CHAMBER_ABSENT_OK if getattr(m, role) is None)
    else:
        extra += (", unit ids " + "/".join(str(u) for u in m.unit_ids)) if m.unit_ids else ""
        extra += ", no position_deg" if m.position_deg is None else ""
    extra += "".join(f", sequence {name} of {len(steps)} writes"
                     for name, steps in m.sequences.items())
    notes = f", {len(m.undocumented)} undocumented points listed" if m.undocumented else ""
    return f"{what} ({kind}, {len(m.registers)} registers{extra}{notes})"


def bits_to_names(word: int, names: dict[int, str]) -> tuple[str, ...]:
    """Decode a bit-field register into the names of the set bits (unknown bits as ``bitN``)."""
    return tuple(names.get(b, f"bit{b}") for b in range(16) if word >> b & 1)


def _load_shipped() -> tuple[dict[str, ChamberMap], dict[str, TurntableMap]]:
    chambers: dict[str, ChamberMap] = {}
    tables: dict[str, TurntableMap] = {}
    for name, path in shipped_maps().items():
        m = load_map(path)
        if isinstance(m, ChamberMap):
            chambers[name] = m
        else:
            tables[name] = m
    return chambers, tables


#: Shipped maps by file name (``drivers/maps/NAME.toml``); loading them at import checks them.
CHAMBER_MAPS, TURNTABLE_MAPS = _load_shipped()
EUROTHERM_3216 = CHAMBER_MAPS["eurotherm-3216"]
WATLOW_F4T = CHAMBER_MAPS["watlow-f4t"]
TWIN_CHAMBER = CHAMBER_MAPS["soakcal-twin-chamber"]
SOAKCAL_TABLE = TURNTABLE_MAPS["soakcal-table"]

# The soakcal table's command values, kept for callers that predate map files.
COMMAND_STOP = SOAKCAL_TABLE.stop_value
COMMAND_MOVE = SOAKCAL_TABLE.move_value
STATUS_IN_POSITION = 1 << SOAKCAL_TABLE.in_position_bit
STATUS_MOVING = 1 << SOAKCAL_TABLE.moving_bit
