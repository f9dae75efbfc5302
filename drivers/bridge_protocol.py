"""Sensor bridge framing: ``$BODY*CK\\r\\n`` ASCII lines, XOR checksum (docs/sensor-bridge.md).

Shared by the driver and the simulated bridge so both sides frame identically.
"""

from __future__ import annotations

from drivers.faults import ProtocolError


def checksum(body: str) -> int:
    """XOR of the body's bytes (NMEA style)."""
    ck = 0
    for b in body.encode("ascii"):
        ck ^= b
    return ck


def encode_frame(*fields: object) -> bytes:
    """Fields joined by commas, framed and terminated."""
    body = ",".join(str(f) for f in fields)
    return f"${body}*{checksum(body):02X}\r\n".encode("ascii")


def decode_frame(line: bytes, device: str = "sensor") -> list[str]:
    """One received line → its fields; ProtocolError on framing or checksum trouble."""
    text = line.decode("ascii", errors="replace").strip()
    if not text.startswith("$") or len(text) < 4 or text[-3] != "*":
        raise ProtocolError(device, f"malformed frame {text[:60]!r}")
    body, ck_text = text[1:-3], text[-2:]
    try:
        ck = int(ck_text, 16)
    except ValueError:
        raise ProtocolError(device, f"bad checksum field in {text[:60]!r}") from None
    if ck != checksum(body):
        raise ProtocolError(device, f"checksum {ck_text} != {checksum(body):02X} in {text[:60]!r}")
    return body.split(",")
