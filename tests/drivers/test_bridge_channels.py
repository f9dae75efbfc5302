"""One bridge multiplexing several sensors: the channel address on the wire (issue 12).

docs/sensor-bridge.md, "Channels": ``@<ch>`` leads every addressed command and each of its
reply lines; unaddressed lines are the one-sensor protocol, byte for byte.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

import numpy as np
import pytest
from test_sensor_bridge import FakeTruth

from drivers.bridge_protocol import channel_field, encode_frame, parse_frame, split_channel
from drivers.clock import VirtualClock
from drivers.faults import ConfigurationFault, DeviceTimeout, ProtocolError
from drivers.sensor_bridge import MultiplexedBridge, SerialAccelerometer
from simulators.bridge_sim import (
    BridgeDevice,
    BridgeServer,
    MultiplexedBridgeDevice,
    start_bridge_server,
)
from simulators.faults import SimFaults

BIASES_G = [(0.01, -0.02, 0.0), (-0.03, 0.005, 0.02), (0.0, 0.04, -0.01)]


def _device(clock: VirtualClock, i: int) -> BridgeDevice:
    return BridgeDevice(
        FakeTruth(bias_g=BIASES_G[i], serial=f"SN-CH{i}"),
        clock,
        np.random.default_rng(i),
        lambda: 25.0,
        lambda: (0.0, 0.0, 0.0),
        faults=SimFaults(),
        board_uid="SIM-MUX-0001",
    )


@dataclass
class MuxRig:
    clock: VirtualClock
    mux: MultiplexedBridgeDevice
    server: BridgeServer
    bridge: MultiplexedBridge


@pytest.fixture
async def mux() -> AsyncIterator[MuxRig]:
    clock = VirtualClock()
    device = MultiplexedBridgeDevice({i: _device(clock, i) for i in range(3)})
    server = await start_bridge_server(device)
    bridge = MultiplexedBridge(server.url, clock, timeout_s=0.3)
    yield MuxRig(clock, device, server, bridge)
    await bridge.close()
    await server.stop()


def test_the_address_field_round_trips_and_a_malformed_one_is_refused() -> None:
    for ch in (0, 7, 99):
        line = encode_frame(channel_field(ch), "AVG", 200)
        assert split_channel(parse_frame(line).fields) == (ch, ["AVG", "200"])
    assert split_channel(["ID"]) == (None, ["ID"])
    for bad in (["@"], ["@x", "ID"], ["@100", "ID"], ["@01", "ID"], ["@-1", "ID"], ["@3"]):
        with pytest.raises(ProtocolError):
            split_channel(bad)
    for bad_ch in (-1, 100, True, 1.0):
        with pytest.raises(ValueError):
            channel_field(bad_ch)  # type: ignore[arg-type]


async def test_each_channel_is_its_own_sensor(mux: MuxRig) -> None:
    assert await mux.bridge.channels() == {0: "SN-CH0", 1: "SN-CH1", 2: "SN-CH2"}
    handles = [mux.bridge.channel(i) for i in range(3)]
    idents = [await h.identify() for h in handles]
    assert [(i.serial, i.channel, i.board_uid) for i in idents] == [
        (f"SN-CH{i}", i, "SIM-MUX-0001") for i in range(3)
    ]
    assert idents[1].as_dict()["channel"] == 1
    await handles[2].configure(4.0, 250.0)  # one channel's range, not the others'
    assert mux.mux.channels[2].truth.range_g == 4.0 and mux.mux.channels[0].truth.range_g == 2.0
    # read at once, as the engine's multi.read_all does: each answer is its own part's
    acqs = await asyncio.gather(*(h.acquire(20) for h in handles))
    for acq, bias in zip(acqs, BIASES_G, strict=True):
        np.testing.assert_allclose(acq.mean_g, np.add(bias, (0.0, 0.0, 1.0)), atol=2e-5)
    raw = [row async for row in handles[1].stream_raw(3)]
    np.testing.assert_allclose(raw[0][0], np.add(BIASES_G[1], (0.0, 0.0, 1.0)), atol=2e-5)


async def test_the_sensors_of_one_bridge_are_read_one_after_the_other(mux: MuxRig) -> None:
    """One command in flight per port: two 20 s captures on one bridge take 40 s."""
    a, b = mux.bridge.channel(0), mux.bridge.channel(1)
    t0 = mux.clock.now()
    await asyncio.gather(a.acquire(2000), b.acquire(2000))  # 2000 / 100 Hz = 20 s each
    assert mux.clock.now() - t0 == pytest.approx(40.0, abs=0.5)


async def test_a_sensor_on_another_bridge_reads_alongside_them(mux: MuxRig) -> None:
    """Queueing is per port: a third sensor on a bridge of its own overlaps the two."""
    other = await start_bridge_server(_device(mux.clock, 2))
    alone = SerialAccelerometer(other.url, mux.clock, timeout_s=0.3)
    try:
        a, b = mux.bridge.channel(0), mux.bridge.channel(1)
        t0 = mux.clock.now()
        await asyncio.gather(a.acquire(2000), b.acquire(2000), alone.acquire(2000))
        assert mux.clock.now() - t0 == pytest.approx(40.0, abs=0.5)  # not 60 s
    finally:
        await alone.close()
        await other.stop()


async def test_unaddressed_lines_are_channel_0_byte_for_byte(mux: MuxRig) -> None:
    """An old host's ID to a multiplexing bridge: the very bytes a one-sensor bridge sends."""
    single = await start_bridge_server(_device(mux.clock, 0))
    try:
        replies = []
        for url in (single.url, mux.server.url):
            reader, writer = await asyncio.open_connection(*url[len("socket://") :].split(":"))
            writer.write(b"$ID*A21B\r\n")
            replies.append(await reader.readline())
            writer.close()
        assert (
            replies[0]
            == replies[1]
            == encode_frame(
                "ID", "ADXL355", "SN-CH0", "soakcal-sim-2.0", "SIM-MUX-0001", "AD", "1D", "ED", "01"
            )
        )
        old_host = SerialAccelerometer(mux.server.url, mux.clock, timeout_s=0.3)
        assert (await old_host.identify()).serial == "SN-CH0"
        await old_host.close()
    finally:
        await single.stop()


async def _lying_bridge(answer: Callable[[list[str]], bytes]) -> asyncio.Server:
    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while line := await reader.readline():
            writer.write(answer(parse_frame(line).fields))
            await writer.drain()
        writer.close()

    return await asyncio.start_server(serve, "127.0.0.1", 0)


ID_FIELDS = ["ID", "ADXL355", "SN-X", "fw", "UID", "AD", "1D", "ED", "01"]


@pytest.mark.parametrize(
    "reply_channel,why",
    [
        ("@2", "carries channel 2, expected channel 1"),
        (None, "carries no channel address, expected channel 1"),
    ],
)
async def test_a_reply_from_another_channel_is_never_taken(
    reply_channel: str | None, why: str
) -> None:
    server = await _lying_bridge(
        lambda f: encode_frame(*([reply_channel] if reply_channel else []), *ID_FIELDS)
    )
    port = server.sockets[0].getsockname()[1]
    bridge = MultiplexedBridge(f"socket://127.0.0.1:{port}", VirtualClock(), timeout_s=0.3)
    try:
        with pytest.raises(ProtocolError, match=why):
            await bridge.channel(1).identify()
        # and an unaddressed host must not take an addressed line either
        plain = SerialAccelerometer(f"socket://127.0.0.1:{port}", VirtualClock(), timeout_s=0.3)
        if reply_channel:
            with pytest.raises(ProtocolError, match="carries channel 2, expected no channel"):
                await plain.identify()
        await plain.close()
    finally:
        await bridge.close()
        server.close()


async def test_one_reply_line_of_a_raw_capture_from_another_channel_fails_it() -> None:
    def answer(f: list[str]) -> bytes:
        n = int(f[2])
        lines = [encode_frame(f[0], "R", i, "00000", "00000", "3E800", 1885) for i in range(n)]
        lines[1] = encode_frame("@0", "R", 1, "00000", "00000", "3E800", 1885)
        return b"".join(lines) + encode_frame(f[0], "END", n)

    server = await _lying_bridge(answer)
    port = server.sockets[0].getsockname()[1]
    bridge = MultiplexedBridge(f"socket://127.0.0.1:{port}", VirtualClock(), timeout_s=0.3)
    try:
        with pytest.raises(ProtocolError, match="channel 0, expected channel 3"):
            [x async for x in bridge.channel(3).stream_raw(3)]
    finally:
        await bridge.close()
        server.close()


async def test_an_empty_channel_and_an_old_bridge_refuse_for_good(mux: MuxRig) -> None:
    with pytest.raises(ConfigurationFault, match="ERR 7 no sensor on channel 5"):
        await mux.bridge.channel(5).identify()
    old = await start_bridge_server(_device(mux.clock, 0))  # a bridge from before channels
    bridge = MultiplexedBridge(old.url, mux.clock, timeout_s=0.3)
    try:
        with pytest.raises(ConfigurationFault, match="no channel addressing"):
            await bridge.channel(1).identify()
        with pytest.raises(ConfigurationFault, match="unknown command CHANNELS"):
            await bridge.channels()
    finally:
        await bridge.close()
        await old.stop()


async def test_a_silent_channel_fails_alone_and_the_others_read_on(mux: MuxRig) -> None:
    mux.mux.channels[1].faults.p_no_reply = 1.0
    handles = [mux.bridge.channel(i) for i in range(3)]
    results = await asyncio.gather(*(h.acquire(10) for h in handles), return_exceptions=True)
    assert isinstance(results[1], DeviceTimeout)
    assert "@1" in results[1].device
    for i in (0, 2):
        np.testing.assert_allclose(
            results[i].mean_g,  # type: ignore[union-attr]
            np.add(BIASES_G[i], (0.0, 0.0, 1.0)),
            atol=2e-5,
        )
    # the port reopened after the timeout; the silent channel's late nothing harms no one
    assert (await handles[2].identify()).serial == "SN-CH2"


async def test_the_port_closes_after_the_last_handle(mux: MuxRig) -> None:
    a, b = mux.bridge.channel(0), mux.bridge.channel(1)
    with pytest.raises(ValueError, match="already in use"):
        mux.bridge.channel(1)
    await a.identify()
    await a.close()
    assert mux.bridge.line._port is not None  # b still holds the line
    assert (await b.identify()).channel == 1
    await b.close()
    assert mux.bridge.line._port is None
