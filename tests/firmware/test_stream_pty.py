"""Plain streaming mode over a pty: hobby-firmware lines, noise on the line, a silent port."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pty_device import PtyDevice

from drivers.clock import VirtualClock
from drivers.faults import DeviceTimeout, ProtocolError
from drivers.sensor_config import StreamFormat
from drivers.stream_sensor import StreamingAccelerometer


def hobby_stream(lines: list[bytes]):  # noqa: ANN201 - a generator-backed callable
    it = itertools.cycle(lines)
    return lambda: next(it)


async def test_labelled_lines_with_banner_and_noise_bytes() -> None:
    lines = [b"X: 10.0 Y: -20.0 Z: 1000.0 T: 21.5\r\n"] * 9 + [b"\xff\xfe garbage\r\n",
                                                           b"ADXL355 demo v1\r\n"]
    dev = PtyDevice(stream=hobby_stream(lines))
    accel = StreamingAccelerometer(dev.path, VirtualClock(), fmt=StreamFormat(units="mg"),
                                   timeout_s=1.0)
    try:
        acq = await accel.acquire(100)
        np.testing.assert_allclose(acq.mean_g, (0.01, -0.02, 1.0))
        assert acq.sensor_c == 21.5 and acq.n == 100
    finally:
        await accel.close()
        dev.close()


async def test_a_stream_of_garbage_is_a_protocol_error() -> None:
    dev = PtyDevice(stream=hobby_stream([b"0.1,0.2\r\n"]))
    accel = StreamingAccelerometer(dev.path, VirtualClock(), timeout_s=1.0)
    try:
        with pytest.raises(ProtocolError, match="not 'x,y,z,t' samples"):
            await accel.acquire(20)
    finally:
        await accel.close()
        dev.close()


async def test_a_silent_port_times_out() -> None:
    dev = PtyDevice()
    accel = StreamingAccelerometer(dev.path, VirtualClock(), timeout_s=0.2)
    try:
        with pytest.raises(DeviceTimeout, match="no line from the stream"):
            await accel.acquire(5)
    finally:
        await accel.close()
        dev.close()
