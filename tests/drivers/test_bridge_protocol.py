"""Bridge framing v2: CRC-16/CCITT-FALSE, 8-bit-safe decoding, v1 only when asked for."""

from __future__ import annotations

import random

import pytest

from drivers.bridge_protocol import (
    crc16_ccitt_false,
    decode_frame,
    encode_frame,
    parse_frame,
    xor_checksum,
)
from drivers.faults import ProtocolError

AVG_BODY = b"AVG,50,1100.500,-2560.250,255998.125,3.100,2.900,3.300,2111.40,2109,2113,0"


def _flip(line: bytes, bit_a: int, bit_b: int) -> bytes:
    b = bytearray(line)
    for bit in (bit_a, bit_b):
        b[bit // 8] ^= 1 << (bit % 8)
    return bytes(b)


def test_crc16_ccitt_false_check_value_and_the_documented_example() -> None:
    assert encode_frame("ID") == b"$ID*A21B\r\n"  # docs/sensor-bridge.md
    # The catalogue check value of CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740).
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF


def test_xor_lets_a_double_flip_through_and_crc_does_not() -> None:
    # The case: the same bit flipped in two bytes cancels in an XOR.
    v1 = encode_frame(*AVG_BODY.decode().split(","), framing="v1")
    v2 = encode_frame(*AVG_BODY.decode().split(","))
    i, j = v1.index(b"1100"), v1.index(b"2560")  # '1' 0x31 and '2' 0x32 differ by 0x03
    bad_v1 = bytearray(v1)
    bad_v1[i] ^= 0x01
    bad_v1[j] ^= 0x01
    assert decode_frame(bytes(bad_v1), framing="v1") != decode_frame(v1, framing="v1")
    bad_v2 = bytearray(v2)
    bad_v2[v2.index(b"1100")] ^= 0x01
    bad_v2[v2.index(b"2560")] ^= 0x01
    with pytest.raises(ProtocolError):
        decode_frame(bytes(bad_v2))


def test_crc_catches_every_double_flip_of_the_same_bit() -> None:
    frame = encode_frame(*AVG_BODY.decode().split(","))
    n_body = len(frame) - 2  # flip anywhere but the CR LF terminator
    rng = random.Random(7)
    pairs = [(8 * a + k, 8 * b + k) for k in range(7)
             for a in range(n_body) for b in range(a + 1, n_body)]
    for bit_a, bit_b in rng.sample(pairs, 4000):
        with pytest.raises(ProtocolError):
            decode_frame(_flip(frame, bit_a, bit_b))


@pytest.mark.parametrize("byte", [0x80, 0xC3, 0xFF, 0x00, 0x07])
def test_high_bit_or_control_byte_is_a_framing_fault_naming_the_column(byte: int) -> None:
    frame = bytearray(encode_frame("ID"))
    frame[2] = byte
    with pytest.raises(ProtocolError, match=f"0x{byte:02X} at column 3"):
        decode_frame(bytes(frame))


def test_v2_link_refuses_a_v1_frame_and_vice_versa() -> None:
    v1 = encode_frame("OK", "CFG", "2", "62.5", framing="v1")
    assert decode_frame(v1, framing="v1") == ["OK", "CFG", "2", "62.5"]
    with pytest.raises(ProtocolError, match="v1 frame on a v2 link"):
        decode_frame(v1)
    with pytest.raises(ProtocolError, match="v2 frame on a v1 link"):
        decode_frame(encode_frame("OK"), framing="v1")
    assert parse_frame(v1).framing == "v1"
    assert v1 == b"$OK,CFG,2,62.5*%02X\r\n" % xor_checksum(b"OK,CFG,2,62.5")


@pytest.mark.parametrize("line", [
    b"", b"\r\n", b"ID*1234\r\n", b"$ID\r\n", b"$ID*12345\r\n", b"$ID*XYZW\r\n",
    b"$I$D*1234\r\n", b"$ID*\r\n", b"$ID*8a3c\r\n",
])
def test_malformed_lines(line: bytes) -> None:
    with pytest.raises(ProtocolError):
        parse_frame(line)


def test_fields_that_cannot_travel_are_refused_before_sending() -> None:
    for bad in ("a,b", "x*y", "$", "tab\there", "µ"):
        with pytest.raises(ValueError):
            encode_frame("ID", bad)
    with pytest.raises(ValueError, match="framing"):
        encode_frame("ID", framing="v3")  # type: ignore[arg-type]


def test_every_one_and_two_bit_error_of_a_short_frame_is_caught() -> None:
    """Exhaustive over a CFG reply, check digits included (only CR LF left alone).

    A body flip changes the CRC by x^(k+16) mod g, of odd weight ≥ 3; one flip in
    a hex digit changes the value by weight 1 or 2, so the two cannot cancel.
    """
    frame = encode_frame("OK", "CFG", "2", "62.5")
    n_bits = 8 * (len(frame) - 2)
    for a in range(n_bits):
        with pytest.raises(ProtocolError):
            decode_frame(_flip1(frame, a))
        for b in range(a + 1, n_bits):
            with pytest.raises(ProtocolError):
                decode_frame(_flip(frame, a, b))


def _flip1(line: bytes, bit: int) -> bytes:
    b = bytearray(line)
    b[bit // 8] ^= 1 << (bit % 8)
    return bytes(b)
