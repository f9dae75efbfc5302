"""Register and sample conversions at their edges."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers import adxl355, codec
from drivers.bridge_protocol import decode_frame, encode_frame
from drivers.faults import ProtocolError
from drivers.registermaps import TWIN_CHAMBER, WATLOW_F4T, Field, bits_to_names


def test_int16_edges() -> None:
    assert codec.to_int16(0x7FFF) == 32767
    assert codec.to_int16(0x8000) == -32768
    assert codec.to_int16(0xFFFF) == -1
    assert codec.from_int16(-1) == 0xFFFF
    assert codec.from_int16(-32768) == 0x8000
    with pytest.raises(ValueError):
        codec.from_int16(32768)
    with pytest.raises(ValueError):
        codec.from_int16(-32769)


def test_scaled_negative_temperatures_one_decimal() -> None:
    f = TWIN_CHAMBER.process_c  # int16, 0.1 °C per count
    assert f.encode(-40.0) == [0xFE70]  # −400 counts
    assert f.decode([0xFE70]) == -40.0
    assert f.decode(f.encode(-0.1)) == pytest.approx(-0.1)
    assert f.decode(f.encode(-3276.8)) == pytest.approx(-3276.8)
    assert f.encode(12.34) == [123]  # rounds to the register's resolution
    with pytest.raises(ValueError):
        f.encode(3276.8)


def test_unsigned_scaled_rejects_negative() -> None:
    with pytest.raises(ValueError):
        TWIN_CHAMBER.ramp_c_per_min.encode(-1.0)


@pytest.mark.parametrize("value", [-40.0, 0.0, 1.5, -273.15, 1e6, float("inf")])
def test_float32_both_word_orders(value: float) -> None:
    hi_first = codec.encode_float32(value, "high_first")
    lo_first = codec.encode_float32(value, "low_first")
    assert lo_first == hi_first[::-1]
    assert codec.decode_float32(hi_first, "high_first") == pytest.approx(value, rel=1e-7)
    assert codec.decode_float32(lo_first, "low_first") == pytest.approx(value, rel=1e-7)


def test_float32_word_order_matters() -> None:
    words = codec.encode_float32(-40.0, "low_first")
    assert words == [0x0000, 0xC220]  # −40.0f = 0xC2200000, low word first
    assert codec.decode_float32(words, "high_first") != -40.0
    assert WATLOW_F4T.process_c.decode(words) == -40.0


def test_float32_nan_survives() -> None:
    assert math.isnan(Field(0, "float32").decode(codec.encode_float32(float("nan"), "high_first")))


def test_bits_to_names() -> None:
    assert bits_to_names(0b101, {0: "a", 2: "c"}) == ("a", "c")
    assert bits_to_names(1 << 9, {}) == ("bit9",)


def test_adxl355_20bit_twos_complement_extremes() -> None:
    assert adxl355.counts_from_20bit(0x7FFFF) == 524287
    assert adxl355.counts_from_20bit(0x80000) == -524288
    assert adxl355.counts_from_20bit(0xFFFFF) == -1
    assert adxl355.counts_from_20bit(0) == 0
    for c in (-524288, -1, 0, 1, 524287):
        assert adxl355.counts_from_20bit(adxl355.counts_to_20bit(c)) == c
    with pytest.raises(ValueError):
        adxl355.counts_to_20bit(524288)


def test_adxl355_sensitivity_per_range() -> None:
    assert adxl355.counts_to_g(256_000, 2.0) == pytest.approx(1.0)
    assert adxl355.counts_to_g(128_000, 4.0) == pytest.approx(1.0)
    assert adxl355.counts_to_g(64_000, 8.0) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        adxl355.lsb_per_g(3.0)
    # Quantisation saturates at the 20-bit limit rather than wrapping.
    assert adxl355.g_to_counts(np.array([10.0, -10.0]), 2.0).tolist() == [524287, -524288]


def test_adxl355_temperature_channel() -> None:
    assert adxl355.temp_raw_to_c(1885) == pytest.approx(25.0)
    assert adxl355.temp_raw_to_c(1885 - 9.05) == pytest.approx(26.0)
    assert adxl355.temp_raw_to_c(adxl355.temp_c_to_raw(-40.0)) == pytest.approx(-40.0, abs=0.06)
    assert adxl355.temp_c_to_raw(-40.0) > adxl355.temp_c_to_raw(60.0)  # negative slope


def test_saturation_flag() -> None:
    assert adxl355.is_saturated(np.array([[512_000, 0, 0]]), 2.0)
    assert not adxl355.is_saturated(np.array([[511_999, 0, 0]]), 2.0)


def test_bridge_frame_roundtrip_and_checksum() -> None:
    frame = encode_frame("AVG", 200, "1.5", -3)
    assert frame.startswith(b"$AVG,200,1.5,-3*") and frame.endswith(b"\r\n")
    assert len(frame.split(b"*")[1].strip()) == 4  # v2: four hex digits of CRC-16
    assert decode_frame(frame) == ["AVG", "200", "1.5", "-3"]
    corrupted = frame.replace(b"1.5", b"1.6")
    with pytest.raises(ProtocolError, match="CRC"):
        decode_frame(corrupted)
    with pytest.raises(ProtocolError):
        decode_frame(b"AVG,200\r\n")
