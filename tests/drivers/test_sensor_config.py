"""Sensor entry of a rig config, and the plain-stream line parser."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.faults import ValueOutOfRange
from drivers.sensor_bridge import SerialAccelerometer
from drivers.sensor_config import (
    SensorConfigError,
    StreamFormat,
    make_accelerometer,
    parse_sensor_config,
    sensor_config_errors,
)
from drivers.stream_sensor import StreamingAccelerometer, parse_stream_line


def test_defaults_are_the_v2_bridge() -> None:
    link = parse_sensor_config({"url": "/dev/ttyACM0"})
    assert (link.protocol, link.framing, link.serial_binding, link.baudrate) == (
        "bridge", "v2", "auto", 115200)
    accel = make_accelerometer(link, VirtualClock())
    assert isinstance(accel, SerialAccelerometer) and accel.framing == "v2"


def test_stream_selection() -> None:
    link = parse_sensor_config({"url": "/dev/ttyUSB0", "protocol": "stream",
                                "serial_binding": "any",
                                "stream": {"units": "m/s2", "columns": ["t", "x", "y", "z"],
                                           "range_g": 4}})
    assert link.stream == StreamFormat("m/s2", ("t", "x", "y", "z"), 4.0)
    assert isinstance(make_accelerometer(link, VirtualClock()), StreamingAccelerometer)


@pytest.mark.parametrize(("cfg", "key"), [
    ({}, "sensors[0].url"),
    ({"url": "x", "baudrate": "fast"}, "sensors[0].baudrate"),
    ({"url": "x", "protocol": "nmea"}, "sensors[0].protocol"),
    ({"url": "x", "framing": "v3"}, "sensors[0].framing"),
    ({"url": "x", "stream": {"units": "furlongs"}}, "sensors[0].stream.units"),
    ({"url": "x", "stream": {"columns": ["x", "y", "z"]}}, "sensors[0].stream.columns"),
    ({"url": "x", "stream": {"range_g": 0}}, "sensors[0].stream.range_g"),
    ({"url": "x", "serial_binding": "scan"}, "sensors[0].serial_binding"),
    ({"url": "x", "serial_binding": "table"}, "sensors[0].serials"),
    ({"url": "x", "serials": {"uid": ""}}, "sensors[0].serials"),
    ({"url": "x", "protocol": "stream", "serial_binding": "eeprom"},
     "sensors[0].serial_binding"),
])
def test_errors_name_the_key(cfg: dict, key: str) -> None:
    assert key in [k for k, _ in sensor_config_errors(cfg)]
    with pytest.raises(SensorConfigError, match=key.replace("[", r"\[").replace("]", r"\]")):
        parse_sensor_config(cfg)


@pytest.mark.parametrize("line", [
    b"0.0123,-0.0456,0.9876,24.50\r\n",
    b"0.0123 -0.0456 0.9876 24.5\n",
    b"X: 0.0123  Y: -0.0456  Z: 0.9876  T: 24.5\r\n",
    b"x=0.0123;y=-0.0456;z=0.9876;t=24.5\n",
    b"0.0123\t-0.0456\t0.9876\t24.5\n",
])
def test_hobby_line_shapes(line: bytes) -> None:
    parsed = parse_stream_line(line, StreamFormat())
    assert parsed is not None
    np.testing.assert_allclose(parsed[0], (0.0123, -0.0456, 0.9876))
    assert parsed[1] == 24.5


def test_units_and_column_order() -> None:
    g, t = parse_stream_line(b"24.5,9.80665,0,-980.665e-2\n",
                             StreamFormat("m/s2", ("t", "x", "y", "z"))) or (None, None)
    np.testing.assert_allclose(g, (1.0, 0.0, -1.0))
    assert t == 24.5
    g, _ = parse_stream_line(b"12.3,-45.6,987.6,20\n", StreamFormat("mg")) or (None, None)
    np.testing.assert_allclose(g, (0.0123, -0.0456, 0.9876))


@pytest.mark.parametrize("line", [
    b"ADXL355 ready\r\n", b"0.1,0.2,0.3\n", b"0.1,0.2,0.3,4,5\n", b"0.1,0.2,\xb10.3,25\n",
    b"nan,0,1,25\n", b"", b"\n",
])
def test_lines_that_are_not_samples(line: bytes) -> None:
    assert parse_stream_line(line, StreamFormat()) is None


async def test_stream_cannot_change_range() -> None:
    accel = StreamingAccelerometer("/dev/null", VirtualClock(), fmt=StreamFormat(range_g=2.0))
    await accel.configure(2.0, 100.0)
    with pytest.raises(ValueOutOfRange, match="stream.range_g"):
        await accel.configure(4.0, 100.0)
