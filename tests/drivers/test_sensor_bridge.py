"""Sensor bridge driver against the simulated bridge: socket:// URL and a pseudo-terminal."""

from __future__ import annotations

import asyncio
import os
import tty
from collections.abc import AsyncIterator
from dataclasses import dataclass

import numpy as np
import pytest

from drivers import adxl355
from drivers.bridge_protocol import decode_frame, encode_frame
from drivers.clock import VirtualClock
from drivers.faults import (
    ConfigurationFault,
    ConnectionLost,
    DeviceTimeout,
    ExceptionReply,
    ValueOutOfRange,
)
from drivers.sensor_bridge import SerialAccelerometer
from simulators.bridge_sim import BridgeDevice, BridgeServer, start_bridge_server
from simulators.faults import SimFaults
from tests.drivers.refusing_port import refusing_port


@dataclass
class FakeTruth:
    """Deterministic stand-in for SensorTruth: output = scale × ref + bias, no noise."""

    bias_g: tuple[float, float, float] = (0.01, -0.02, 0.0)
    scale: float = 1.0
    odr_hz: float = 100.0
    range_g: float = 2.0
    serial: str = "FAKE-1"

    def sample_g(self, ref_g: np.ndarray, die_c: float, n: int, rng: np.random.Generator,
                 t_s: float = 0.0, lab_to_sensor: np.ndarray | None = None) -> np.ndarray:
        out = self.scale * np.asarray(ref_g) + np.asarray(self.bias_g)
        return np.clip(np.tile(out, (n, 1)), -self.range_g, self.range_g)

    def temperature_samples_c(self, die_c: float, n: int,
                              rng: np.random.Generator) -> np.ndarray:
        return np.full(n, die_c)


@dataclass
class BridgeRig:
    clock: VirtualClock
    device: BridgeDevice
    server: BridgeServer
    sensor: SerialAccelerometer


@pytest.fixture
async def bridge() -> AsyncIterator[BridgeRig]:
    clock = VirtualClock()
    device = BridgeDevice(FakeTruth(), clock, np.random.default_rng(1), lambda: -20.0,
                          lambda: (90.0, 0.0, 0.0), faults=SimFaults())
    server = await start_bridge_server(device)
    sensor = SerialAccelerometer(server.url, clock, timeout_s=0.3)
    yield BridgeRig(clock, device, server, sensor)
    await sensor.close()
    await server.stop()


async def test_identify_and_configure(bridge: BridgeRig) -> None:
    ident = await bridge.sensor.identify()
    assert (ident.model, ident.serial) == ("ADXL355", "FAKE-1")
    assert (ident.devid_ad, ident.devid_mst, ident.partid) == (0xAD, 0x1D, 0xED)
    assert ident.board_uid == "SIM-BRIDGE-0001" and ident.protocol == "v2"
    assert ident.as_dict()["partid"] == "0xED"
    await bridge.sensor.configure(4.0, 250.0)
    assert bridge.device.truth.range_g == 4.0 and bridge.sensor.odr_hz == 250.0
    with pytest.raises(ValueOutOfRange):
        await bridge.sensor.configure(3.0, 100.0)


@pytest.mark.parametrize("mode", ["average", "raw"])
async def test_acquire_follows_orientation_and_temperature(bridge: BridgeRig, mode: str) -> None:
    bridge.sensor.mode = mode  # type: ignore[assignment]
    acq = await bridge.sensor.acquire(50)
    # Outer axis at +90°: sensor +y up (drivers.geometry), plus the fake bias.
    np.testing.assert_allclose(acq.mean_g, (0.01, 0.98, 0.0), atol=1 / 256_000)
    assert acq.n == 50
    assert acq.sd_g == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert acq.sensor_c == pytest.approx(-20.0, abs=0.06)  # 12-bit channel resolution
    assert not acq.saturated
    assert acq.duration_s == pytest.approx(0.5)  # 50 samples at 100 Hz, clock time


async def test_saturation_is_flagged(bridge: BridgeRig) -> None:
    bridge.device.truth.scale = 3.0  # 3 g on a ±2 g range
    for mode in ("average", "raw"):
        bridge.sensor.mode = mode  # type: ignore[assignment]
        assert (await bridge.sensor.acquire(5)).saturated


async def test_stream_raw(bridge: BridgeRig) -> None:
    frames = [f async for f in bridge.sensor.stream_raw(4)]
    assert len(frames) == 4
    np.testing.assert_allclose(frames[0][0], (0.01, 0.98, 0.0), atol=1e-5)


async def test_permanent_refusal_is_a_configuration_fault(bridge: BridgeRig) -> None:
    with pytest.raises(ConfigurationFault, match=r"ERR 3 n must be 1\.\.100000") as err:
        await bridge.sensor.acquire(10**6)
    assert not err.value.retryable and err.value.code == 3
    assert isinstance(err.value, ExceptionReply)  # older callers' except clauses still match


async def test_v1_host_against_a_v2_bridge(bridge: BridgeRig) -> None:
    """A host configured for v1 framing (bridges in the field) gets v1 answers."""
    old = SerialAccelerometer(bridge.server.url, bridge.clock, timeout_s=0.3, framing="v1")
    try:
        ident = await old.identify()
        assert (ident.serial, ident.partid, ident.protocol) == ("FAKE-1", None, "v1")
        acq = await old.acquire(20)
        np.testing.assert_allclose(acq.mean_g, (0.01, 0.98, 0.0), atol=1 / 256_000)
    finally:
        await old.close()
    with pytest.raises(ValueError, match="framing"):
        SerialAccelerometer("socket://x:1", bridge.clock, framing="v3")  # type: ignore[arg-type]


async def test_faults_recovered_or_reported(bridge: BridgeRig) -> None:
    f = bridge.device.faults
    f.p_exception = 1.0
    with pytest.raises(ExceptionReply):
        await bridge.sensor.identify()
    f.p_exception = 0.0
    f.p_no_reply = 1.0
    with pytest.raises(DeviceTimeout):
        await bridge.sensor.identify()
    f.p_no_reply = 0.0
    f.p_drop = 1.0
    with pytest.raises((ConnectionLost, DeviceTimeout)):
        await bridge.sensor.identify()
    f.p_drop = 0.0
    assert (await bridge.sensor.identify()).model == "ADXL355"  # reopened by itself


async def test_server_gone_is_connection_lost(bridge: BridgeRig) -> None:
    await bridge.server.stop()
    with refusing_port(bridge.server.port) as port:
        sensor = SerialAccelerometer(f"socket://127.0.0.1:{port}", bridge.clock, timeout_s=0.2)
        with pytest.raises(ConnectionLost):
            await sensor.identify()


async def test_works_over_a_pseudo_terminal() -> None:
    """The same driver on a pty: the device side answers on the master fd."""
    clock = VirtualClock()
    device = BridgeDevice(FakeTruth(), clock, np.random.default_rng(2), lambda: 25.0,
                          lambda: (0.0, 0.0, 0.0))
    master, slave = os.openpty()
    tty.setraw(slave)  # no echo, no newline translation: a clean 8-bit line
    loop = asyncio.get_running_loop()
    buf = bytearray()

    def on_readable() -> None:
        buf.extend(os.read(master, 4096))
        while b"\n" in buf:
            line, _, rest = bytes(buf).partition(b"\n")
            buf[:] = rest
            loop.create_task(reply(line + b"\n"))

    async def reply(line: bytes) -> None:
        for frame in await device.handle(decode_frame(line)):
            os.write(master, frame)

    loop.add_reader(master, on_readable)
    sensor = SerialAccelerometer(os.ttyname(slave), clock, timeout_s=1.0)
    try:
        assert (await sensor.identify()).serial == "FAKE-1"
        acq = await sensor.acquire(10)
        np.testing.assert_allclose(acq.mean_g, (0.01, -0.02, 1.0), atol=1e-5)
        assert acq.sensor_c == pytest.approx(25.0, abs=0.06)
    finally:
        loop.remove_reader(master)
        await sensor.close()
        os.close(master)
        os.close(slave)


def test_temperature_code_of_fake_is_consistent() -> None:
    assert adxl355.temp_raw_to_c(adxl355.temp_c_to_raw(-20.0)) == pytest.approx(-20.0, abs=0.06)


async def test_cancelled_capture_leaves_driver_usable(bridge: BridgeRig) -> None:
    bridge.device.faults.p_no_reply = 1.0
    bridge.sensor.timeout_s = 5.0
    task = asyncio.create_task(bridge.sensor.identify())
    await asyncio.sleep(0.2)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    bridge.device.faults.p_no_reply = 0.0
    bridge.sensor.timeout_s = 0.5
    assert (await bridge.sensor.identify()).model == "ADXL355"


async def test_noise_without_newline_does_not_kill_the_simulated_bridge(
        bridge: BridgeRig) -> None:
    reader, writer = await asyncio.open_connection(bridge.server.host, bridge.server.port)
    try:
        writer.write(b"\x80" * 70_000 + b"\n" + encode_frame("ID"))
        await writer.drain()
        first = await asyncio.wait_for(reader.readline(), 2.0)
        assert decode_frame(first)[:2] == ["ERR", "2"]
        assert decode_frame(await asyncio.wait_for(reader.readline(), 2.0))[0] == "ID"
    finally:
        writer.close()


async def test_binding_a_serial_on_the_simulated_fixture(bridge: BridgeRig) -> None:
    assert (await bridge.sensor.identify()).serial == "FAKE-1"
    assert await bridge.sensor.bind_serial("SN-K9") == "SN-K9"
    assert (await bridge.sensor.identify()).serial == "SN-K9"
    with pytest.raises(ValueOutOfRange):
        await bridge.sensor.bind_serial("")
