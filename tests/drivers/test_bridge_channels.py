"""One bridge multiplexing several sensors: the channel address on the wire (issue 12).

docs/sensor-bridge.md, "Channels": ``@<ch>`` leads every addressed command and each of its
reply lines; unaddressed lines are the one-sensor protocol, byte for byte.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

import numpy as np
import pytest
from test_sensor_bridge import FakeTruth

from drivers.bridge_protocol import channel_field, encode_frame, parse_frame, split_channel
from drivers.clock import VirtualClock
from drivers.faults import ConfigurationFault, DeviceTimeout, ExceptionReply, ProtocolError
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
    # These tests time overlapping captures on two servers: a request still in flight must
    # not let time jump past it, whatever the machine's load. The clock moves only when the
    # event loop (the servers run on it) and the serial ports' reads are quiet.
    clock = VirtualClock(idle="loop")
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
    # read at once, as the engine's sensors.read_all does: each answer is its own part's
    acqs = await asyncio.gather(*(h.acquire(20) for h in handles))
    for acq, bias in zip(acqs, BIASES_G, strict=True):
        np.testing.assert_allclose(acq.mean_g, np.add(bias, (0.0, 0.0, 1.0)), atol=2e-5)
    raw = [row async for row in handles[1].stream_raw(3)]
    np.testing.assert_allclose(raw[0][0], np.add(BIASES_G[1], (0.0, 0.0, 1.0)), atol=2e-5)


async def test_the_channels_of_one_bridge_capture_together(mux: MuxRig) -> None:
    """Reads started together (as sensors.read_all does) are one group capture: two 20 s
    captures on one bridge take 20 s, a lone read still its own 20 s after them."""
    a, b = mux.bridge.channel(0), mux.bridge.channel(1)
    t0 = mux.clock.now()
    acqs = await asyncio.gather(a.acquire(2000), b.acquire(2000))  # 2000 / 100 Hz = 20 s
    assert mux.clock.now() - t0 == pytest.approx(20.0, abs=0.5)
    for acq, bias in zip(acqs, BIASES_G[:2], strict=True):
        np.testing.assert_allclose(acq.mean_g, np.add(bias, (0.0, 0.0, 1.0)), atol=2e-5)
        assert acq.n == 2000 and acq.duration_s == pytest.approx(20.0, abs=0.5)
    t1 = mux.clock.now()
    await b.acquire(2000)
    assert mux.clock.now() - t1 == pytest.approx(20.0, abs=0.5)


async def test_a_sensor_on_another_bridge_reads_alongside_them(mux: MuxRig) -> None:
    """A third sensor on a bridge of its own overlaps the group: all three in 20 s."""
    other = await start_bridge_server(_device(mux.clock, 2))
    alone = SerialAccelerometer(other.url, mux.clock, timeout_s=0.3)
    try:
        a, b = mux.bridge.channel(0), mux.bridge.channel(1)
        t0 = mux.clock.now()
        await asyncio.gather(a.acquire(2000), b.acquire(2000), alone.acquire(2000))
        assert mux.clock.now() - t0 == pytest.approx(20.0, abs=0.5)  # not 40 s, not 60 s
    finally:
        await alone.close()
        await other.stop()


async def test_a_bridge_without_the_group_command_is_read_channel_by_channel(
    mux: MuxRig, caplog: pytest.LogCaptureFixture
) -> None:
    """Firmware 2.1 answers the group command ERR 1: the host says so once in the log and
    reads its channels one after the other from then on (each its own data)."""
    mux.mux.group_capture = False
    handles = [mux.bridge.channel(i) for i in range(3)]
    for _ in range(2):
        t0 = mux.clock.now()
        with caplog.at_level(logging.WARNING, logger="drivers.sensor_bridge"):
            acqs = await asyncio.gather(*(h.acquire(2000) for h in handles))
        assert mux.clock.now() - t0 == pytest.approx(60.0, abs=0.5)
        for acq, bias in zip(acqs, BIASES_G, strict=True):
            np.testing.assert_allclose(acq.mean_g, np.add(bias, (0.0, 0.0, 1.0)), atol=2e-5)
    warned = [r for r in caplog.records if "refuses the group capture" in r.getMessage()]
    assert len(warned) == 1 and "unknown command" in warned[0].getMessage()
    assert mux.bridge.group_capture is False


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
    """In a group its line is missing (a ProtocolError of its own); alone it times out."""
    mux.mux.channels[1].faults.p_no_reply = 1.0
    handles = [mux.bridge.channel(i) for i in range(3)]
    results = await asyncio.gather(*(h.acquire(10) for h in handles), return_exceptions=True)
    assert isinstance(results[1], ProtocolError)
    assert "@1" in results[1].device and "no reply line for channel 1" in str(results[1])
    for i in (0, 2):
        np.testing.assert_allclose(
            results[i].mean_g,  # type: ignore[union-attr]
            np.add(BIASES_G[i], (0.0, 0.0, 1.0)),
            atol=2e-5,
        )
    with pytest.raises(DeviceTimeout):  # its retry goes alone: @1,AVG,10, never answered
        await handles[1].acquire(10)
    # the port reopened after the timeout; the silent channel's late nothing harms no one
    assert (await handles[2].identify()).serial == "SN-CH2"


async def test_a_channel_s_err_line_fails_it_alone(mux: MuxRig) -> None:
    """Busy on channel 0 (ERR 6, retryable) and no sensor on channel 5 (ERR 7, for good)."""
    mux.mux.channels[0].faults.p_exception = 1.0
    handles = [mux.bridge.channel(i) for i in (0, 1, 5)]
    results = await asyncio.gather(*(h.acquire(10) for h in handles), return_exceptions=True)
    assert type(results[0]) is ExceptionReply and results[0].code == 6
    assert "@0" in results[0].device
    assert isinstance(results[2], ConfigurationFault)
    assert "ERR 7 no sensor on channel 5" in str(results[2]) and "'@5,AVG,10'" in str(results[2])
    np.testing.assert_allclose(
        results[1].mean_g,  # type: ignore[union-attr]
        np.add(BIASES_G[1], (0.0, 0.0, 1.0)),
        atol=2e-5,
    )


# --- group capture against a bridge that lies: each reply line goes to its address only ---
def _avg_line(address: str, mean_x: float) -> bytes:
    return encode_frame(
        address,
        "AVG",
        10,
        f"{mean_x:.3f}",
        "0.000",
        "256000.000",
        "1.000",
        "1.000",
        "1.000",
        "1885.00",
        1885,
        1885,
        0,
    )


def _group_reply(order: list[str], end: bool = True) -> Callable[[list[str]], bytes]:
    """Answer ``AVG,10,@0,@1,@2`` with a line per address of ``order`` (channel ch reads
    x = 1000·(ch + 1) counts under its own address), then END."""

    def answer(f: list[str]) -> bytes:
        assert f[:2] == ["AVG", "10"] and f[2:] == ["@0", "@1", "@2"]
        lines = [_avg_line(a, 1000.0 * (int(a[1:]) + 1)) for a in order]
        return b"".join(lines) + (encode_frame("END", "AVG", len(order)) if end else b"")

    return answer


async def _read_group(answer: Callable[[list[str]], bytes]) -> list[object]:
    server = await _lying_bridge(answer)
    port = server.sockets[0].getsockname()[1]
    bridge = MultiplexedBridge(f"socket://127.0.0.1:{port}", VirtualClock(), timeout_s=0.3)
    try:
        handles = [bridge.channel(i) for i in range(3)]
        return await asyncio.gather(*(h.acquire(10) for h in handles), return_exceptions=True)
    finally:
        await bridge.close()
        server.close()


def _x_counts(result: object) -> float:
    assert not isinstance(result, BaseException), result
    return round(result.mean_g[0] * 256000.0, 3)  # type: ignore[attr-defined]


async def test_group_reply_lines_go_to_their_address_in_any_order() -> None:
    results = await _read_group(_group_reply(["@2", "@0", "@1"]))
    assert [_x_counts(r) for r in results] == [1000.0, 2000.0, 3000.0]


async def test_a_channel_swap_on_the_wire_is_a_protocol_error_for_those_channels() -> None:
    """Channel 1's line labelled @0: @0 has two lines, @1 none; neither is taken, @2 is."""
    results = await _read_group(_group_reply(["@0", "@0", "@2"]))
    assert isinstance(results[0], ProtocolError)
    assert "2 reply lines for channel 0" in str(results[0])
    assert isinstance(results[1], ProtocolError)
    assert "no reply line for channel 1" in str(results[1])
    assert _x_counts(results[2]) == 3000.0


async def test_a_line_for_a_channel_not_asked_is_never_taken() -> None:
    results = await _read_group(_group_reply(["@0", "@7", "@2"]))
    assert isinstance(results[1], ProtocolError)
    assert "a line for channel 7 not asked" in str(results[1])
    assert [_x_counts(results[0]), _x_counts(results[2])] == [1000.0, 3000.0]


async def test_a_garbled_group_line_fails_only_its_channel() -> None:
    def answer(f: list[str]) -> bytes:
        good = _group_reply(["@0", "@1", "@2"])(f)
        lines = good.split(b"\n")
        lines[1] = lines[1].replace(b"2000.000", b"2001.000")  # a digit hit on the line
        return b"\n".join(lines)

    results = await _read_group(answer)
    assert isinstance(results[1], ProtocolError) and "CRC" in str(results[1])
    assert [_x_counts(results[0]), _x_counts(results[2])] == [1000.0, 3000.0]


async def test_a_group_without_end_delivers_what_came_and_times_out_the_rest() -> None:
    results = await _read_group(_group_reply(["@0", "@2"], end=False))
    assert isinstance(results[1], DeviceTimeout)
    assert [_x_counts(results[0]), _x_counts(results[2])] == [1000.0, 3000.0]


async def test_a_refused_group_command_fails_every_member_with_its_own_name() -> None:
    results = await _read_group(lambda f: encode_frame("ERR", 3, "n must be 1..5"))
    assert all(isinstance(r, ConfigurationFault) for r in results)
    assert [r.device for r in results] == ["sensor @0", "sensor @1", "sensor @2"]  # type: ignore[union-attr]
    assert "'AVG,10,@0,@1,@2'" in str(results[0])


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


async def test_cancelled_group_reads_leave_the_bridge_usable() -> None:
    """An abort cancels a position's reads while the group waits for its reply: the group
    is given up (its port handed to the reading thread to close), and the next reads,
    grouped again on a fresh port, get their own answers."""
    commands: list[list[str]] = []

    def answer(f: list[str]) -> bytes:
        commands.append(f)
        return b"" if len(commands) == 1 else _group_reply(["@0", "@1", "@2"])(f)

    server = await _lying_bridge(answer)
    port = server.sockets[0].getsockname()[1]
    bridge = MultiplexedBridge(f"socket://127.0.0.1:{port}", VirtualClock(), timeout_s=0.5)
    try:
        handles = [bridge.channel(i) for i in range(3)]
        reads = asyncio.gather(*(h.acquire(10) for h in handles))
        while not commands:  # the group command is out, its reply never comes
            await asyncio.sleep(0.01)
        groups = list(bridge._running)
        reads.cancel()
        with pytest.raises(asyncio.CancelledError):
            await reads
        await asyncio.gather(*groups, return_exceptions=True)
        assert len(groups) == 1 and groups[0].cancelled()  # nobody waits: the group stops
        again = await asyncio.gather(*(h.acquire(10) for h in handles))
        assert [_x_counts(r) for r in again] == [1000.0, 2000.0, 3000.0]
        assert commands == [["AVG", "10", "@0", "@1", "@2"]] * 2
    finally:
        await bridge.close()
        server.close()


async def test_two_reads_of_one_channel_in_one_turn_both_answer(mux: MuxRig) -> None:
    a, b = mux.bridge.channel(0), mux.bridge.channel(1)
    got = await asyncio.gather(a.acquire(20), a.acquire(20), b.acquire(20))
    assert [g.n for g in got] == [20, 20, 20]
