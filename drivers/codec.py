"""Register-level conversions: signed 16-bit, scaled integers, 32-bit floats in either word order.

Pure functions, no I/O: the drivers and the simulators share them, so a
round trip through the wire is exact by construction and testable at the edges.
"""

from __future__ import annotations

import struct
from typing import Literal

WordOrder = Literal["high_first", "low_first"]


def to_int16(word: int) -> int:
    """Interpret one 16-bit register as two's complement."""
    word &= 0xFFFF
    return word - 0x10000 if word & 0x8000 else word


def from_int16(value: int) -> int:
    """Encode a signed integer into one register; raises ValueError outside −32768…32767."""
    if not -0x8000 <= value <= 0x7FFF:
        raise ValueError(f"{value} does not fit a signed 16-bit register (-32768..32767)")
    return value & 0xFFFF


def decode_scaled(word: int, scale: float, signed: bool = True) -> float:
    """Scaled integer register → engineering value (e.g. 0.1 °C per count: scale=10)."""
    raw = to_int16(word) if signed else word & 0xFFFF
    return raw / scale


def encode_scaled(value: float, scale: float, signed: bool = True) -> int:
    """Engineering value → scaled integer register, rounded to the nearest count."""
    raw = int(round(value * scale))
    if signed:
        return from_int16(raw)
    if not 0 <= raw <= 0xFFFF:
        raise ValueError(f"{value} × {scale} does not fit an unsigned 16-bit register")
    return raw


def decode_float32(words: list[int] | tuple[int, ...], word_order: WordOrder) -> float:
    """Two registers → IEEE-754 single; ``low_first`` is the Watlow/"CDAB" convention."""
    if len(words) != 2:
        raise ValueError(f"a 32-bit float needs 2 registers, got {len(words)}")
    hi, lo = (words[0], words[1]) if word_order == "high_first" else (words[1], words[0])
    return struct.unpack(">f", struct.pack(">HH", hi & 0xFFFF, lo & 0xFFFF))[0]


def encode_float32(value: float, word_order: WordOrder) -> list[int]:
    """IEEE-754 single → two registers in the given word order (bytes big-endian within a word)."""
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return [hi, lo] if word_order == "high_first" else [lo, hi]
