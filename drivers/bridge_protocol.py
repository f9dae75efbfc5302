"""Sensor bridge framing (docs/sensor-bridge.md), shared by the driver and the simulated bridge.

Protocol v2 frames a line as ``$BODY*CCCC\\r\\n`` where ``CCCC`` is the
CRC-16/CCITT-FALSE of the body's bytes (poly 0x1021, init 0xFFFF, no
reflection, no final XOR; check value ``CRC("123456789") = 0x29B1``). Unlike the
v1 XOR byte, the CRC catches every one- and two-bit error of a line (check
digits included: tests/drivers/test_bridge_protocol.py enumerates them) and
every burst up to 16 bits within the body, so two flips of the same bit in two
bytes no longer cancel.

The v1 framing (``$BODY*CK``, XOR of the bytes, 2 hex digits) stays readable
for bridges already in the field, but only when the link is configured for it
(``framing="v1"``): a v2 link refuses a v1 frame instead of guessing, so a line
error can never downgrade the check. Bytes are decoded without assuming ASCII:
anything outside printable 7-bit ASCII is a framing fault naming its column.
"""

from __future__ import annotations

import binascii
import re
from dataclasses import dataclass
from typing import Literal

from drivers.faults import ProtocolError

Framing = Literal["v2", "v1"]
FRAMINGS: tuple[Framing, ...] = ("v2", "v1")


def crc16_ccitt_false(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, MSB first, no final XOR).

    ``binascii.crc_hqx`` is this CRC (the same polynomial, MSB first, no final XOR) with
    the initial value given: computed in C, not a byte at a time in Python.
    """
    return binascii.crc_hqx(data, crc)


def xor_checksum(data: bytes) -> int:
    """The v1 (NMEA-style) XOR of the body's bytes; kept only to read v1 bridges."""
    ck = 0
    for b in data:
        ck ^= b
    return ck


def checksum(body: str) -> int:
    """v1 XOR checksum of a text body (kept for callers of the v1 API)."""
    return xor_checksum(body.encode("ascii"))


def encode_frame(*fields: object, framing: Framing = "v2") -> bytes:
    """Fields joined by commas, framed and terminated; ValueError on a field that cannot travel."""
    texts = [str(f) for f in fields]
    for i, text in enumerate(texts):
        bad = _CANNOT_TRAVEL.search(text)
        if bad:
            raise ValueError(f"field {i} {text[:40]!r}: {bad.group()!r} cannot travel in a "
                             "bridge frame")
    body = ",".join(texts).encode("ascii")
    if framing == "v2":
        return b"$" + body + b"*%04X\r\n" % crc16_ccitt_false(body)
    if framing == "v1":
        return b"$" + body + b"*%02X\r\n" % xor_checksum(body)
    raise ValueError(f"unknown bridge framing {framing!r} (expected v2 or v1)")


# A field's character that cannot travel (outside printable ASCII, or a delimiter), and a
# received byte outside printable 7-bit ASCII: the first one found is the one named.
_CANNOT_TRAVEL = re.compile(r"[^ -~]|[$*,]")
_NOT_PRINTABLE = re.compile(rb"[^\x20-\x7e]")


@dataclass(frozen=True)
class Frame:
    fields: list[str]
    framing: Framing


def parse_frame(line: bytes, device: str = "sensor") -> Frame:
    """One received line in either framing → its fields and framing; ProtocolError on any fault.

    The framing is told by the checksum's width (4 hex digits v2, 2 hex digits
    v1); callers that must not accept v1 use :func:`decode_frame`.
    """
    raw = line.rstrip(b"\r\n")
    bad = _NOT_PRINTABLE.search(raw)
    if bad:
        raise ProtocolError(device, f"byte 0x{raw[bad.start()]:02X} at column {bad.start() + 1} "
                                    f"is not printable ASCII in {_show(raw)}")
    if not raw.startswith(b"$"):
        raise ProtocolError(device, f"frame does not start with '$': {_show(raw)}")
    star = raw.rfind(b"*")
    if star < 1:
        raise ProtocolError(device, f"frame has no '*' checksum separator: {_show(raw)}")
    body, ck_text = raw[1:star], raw[star + 1:]
    if b"$" in body or b"*" in body:
        raise ProtocolError(device, f"delimiter inside a frame body: {_show(raw)}")
    if len(ck_text) not in (2, 4) or any(c not in b"0123456789ABCDEF" for c in ck_text):
        raise ProtocolError(device, f"bad checksum field {ck_text.decode()!r} in {_show(raw)}")
    ck = int(ck_text, 16)
    if len(ck_text) == 4:
        framing: Framing = "v2"
        want = crc16_ccitt_false(body)
        if ck != want:
            raise ProtocolError(device, f"CRC {ck:04X} != {want:04X} in {_show(raw)}")
    else:
        framing = "v1"
        want = xor_checksum(body)
        if ck != want:
            raise ProtocolError(device, f"checksum {ck:02X} != {want:02X} in {_show(raw)}")
    return Frame(body.decode("ascii").split(","), framing)


def decode_frame(line: bytes, device: str = "sensor", framing: Framing = "v2") -> list[str]:
    """One received line → its fields, refusing a frame of the other framing (no downgrade)."""
    frame = parse_frame(line, device)
    if frame.framing != framing:
        raise ProtocolError(device, f"{frame.framing} frame on a {framing} link "
                                    f"(set the sensor's framing to {frame.framing} if the "
                                    f"bridge really speaks it): {_show(line.rstrip())}")
    return frame.fields


def _show(raw: bytes) -> str:
    """A line for an error message: printable ASCII kept, anything else as \\xNN, 60 bytes max."""
    return repr(raw[:60].decode("ascii", errors="backslashreplace"))


# --- channel address (a bridge multiplexing N sensors; docs/sensor-bridge.md, "Channels") ---
#: A channel-addressed line starts with the field ``@<ch>``: ``$@1,AVG,200*CCCC``, and every
#: reply line to it carries the same field first. A line without it is the pre-channel form
#: (what single-sensor bridges and hosts always sent), which a multiplexing bridge answers
#: for channel 0, unaddressed: old hosts keep their bytes.
CHANNEL_MARK = "@"
MAX_CHANNEL = 99  # two decimal digits on the wire; a board hosts as many as its chip selects


def channel_field(channel: int) -> str:
    """The address field of ``channel``; ``ValueError`` outside 0…:data:`MAX_CHANNEL`."""
    if isinstance(channel, bool) or not isinstance(channel, int) or \
            not 0 <= channel <= MAX_CHANNEL:
        raise ValueError(f"bridge channel must be an integer 0..{MAX_CHANNEL}, got {channel!r}")
    return f"{CHANNEL_MARK}{channel}"


def split_channel(fields: list[str], device: str = "sensor") -> tuple[int | None, list[str]]:
    """``["@2", "AVG", …]`` → ``(2, ["AVG", …])``; unaddressed fields → ``(None, fields)``.

    A malformed address (``@``, ``@x``, ``@100``, ``@01``) is a :class:`ProtocolError`:
    it can only come from a line fault or a bridge that does not speak this protocol.
    """
    head = fields[0] if fields else ""
    if not head.startswith(CHANNEL_MARK):
        return None, fields
    digits = head[len(CHANNEL_MARK):]
    if not digits.isdigit() or not digits.isascii() or str(int(digits)) != digits or \
            int(digits) > MAX_CHANNEL:
        raise ProtocolError(device, f"bad channel address {head!r} (expected @0..@{MAX_CHANNEL})")
    if len(fields) < 2:
        raise ProtocolError(device, f"channel address {head!r} with no command or reply after it")
    return int(digits), fields[1:]
