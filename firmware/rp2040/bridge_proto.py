# soakcal sensor bridge: line framing, firmware side (docs/sensor-bridge.md, protocol v2).
#
# MicroPython and CPython both run this file unchanged: no typing imports, no
# f-strings with nested specs, bytes in and bytes out. The host's reference is
# drivers/bridge_protocol.py; tests/firmware checks that both frame identically.

_POLY = 0x1021


def _table():
    t = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ _POLY) if crc & 0x8000 else crc << 1
        t.append(crc & 0xFFFF)
    return t


_CRC_TABLE = _table()


def crc16(data, crc=0xFFFF):
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, MSB first, no final XOR."""
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ _CRC_TABLE[((crc >> 8) ^ b) & 0xFF]
    return crc


def xor8(data):
    """v1 checksum: XOR of the body's bytes (answering hosts not yet on v2)."""
    ck = 0
    for b in data:
        ck ^= b
    return ck


def frame(fields, v1=False):
    """List of fields -> one framed line; the body is plain ASCII by construction."""
    body = ",".join([str(f) for f in fields]).encode()
    if v1:
        return b"$" + body + f"*{xor8(body):02X}\r\n".encode()
    return b"$" + body + f"*{crc16(body):04X}\r\n".encode()


def unframe(line):
    """One received line -> (fields, is_v1), or None for any framing fault.

    Bytes outside printable ASCII are a fault (never decoded as text), so a
    noise burst on the line is answered with ERR 2 instead of crashing.
    """
    raw = line.rstrip(b"\r\n")
    for b in raw:
        if b < 0x20 or b > 0x7E:
            return None
    star = raw.rfind(b"*")
    if len(raw) < 4 or raw[0] != 0x24 or star < 1:  # 0x24 = '$'
        return None
    body = raw[1:star]
    ck = raw[star + 1:]
    if b"$" in body or b"*" in body or len(ck) not in (2, 4):
        return None
    for c in ck:  # upper-case hex only: a flipped case bit is a line error too
        if not (0x30 <= c <= 0x39 or 0x41 <= c <= 0x46):
            return None
    value = int(ck, 16)
    if len(ck) == 4:
        if value != crc16(body):
            return None
        return body.decode().split(","), False
    if value != xor8(body):
        return None
    return body.decode().split(","), True
