"""The reference firmware multiplexing three ADXL355 on one SPI bus, over a pty (issue 12).

Each channel is its own register-level chip (its own chip select on the board) with its
own fixture EEPROM; the host drives them through ``drivers.sensor_bridge.MultiplexedBridge``.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import adxl355_spi
import bridge_app
import bridge_proto
import fixture_eeprom
import numpy as np
import pytest
from pty_device import PtyDevice
from test_firmware import UID, MemI2C

from drivers.bridge_protocol import encode_frame
from drivers.clock import VirtualClock
from drivers.faults import ConfigurationFault
from drivers.sensor_bridge import MultiplexedBridge, SerialAccelerometer
from simulators.adxl355_regs import ADXL355Registers

TRUE_G = [(0.0123, -0.0456, 0.9876), (-0.5, 0.25, 0.8), (0.7, 0.0, -0.7)]
DIE_C = [-12.5, 0.0, 40.0]


def _channel(i: int) -> tuple[ADXL355Registers, bridge_app.Bridge]:
    chip = ADXL355Registers(lambda: TRUE_G[i], lambda: DIE_C[i], rng=np.random.default_rng(i))
    eeprom = fixture_eeprom.FixtureEeprom(MemI2C())
    eeprom.write_serial(f"SN-F{i}")
    return chip, bridge_app.Bridge(adxl355_spi.ADXL355(chip), UID, eeprom)


@pytest.fixture
def board() -> Iterator[tuple[list[ADXL355Registers], bridge_app.MuxBridge, PtyDevice]]:
    parts = [_channel(i) for i in range(3)]
    mux = bridge_app.MuxBridge({i: b for i, (_c, b) in enumerate(parts)})
    dev = PtyDevice(on_line=mux.handle_line)
    yield [c for c, _b in parts], mux, dev
    dev.close()


def test_unaddressed_lines_get_the_one_sensor_bridge_s_bytes() -> None:
    _chip, single = _channel(0)
    mux = bridge_app.MuxBridge({0: _channel(0)[1], 1: _channel(1)[1]})
    for line in (
        b"$ID*A21B\r\n",
        encode_frame("ID", framing="v1"),
        encode_frame("AVG", 5),
        encode_frame("CFG", 4, 250),
        encode_frame("AVG", 0),
        b"$ID*0000\r\n",
    ):
        assert mux.handle_line(line) == single.handle_line(line)


def test_addressed_replies_carry_their_channel_on_every_line() -> None:
    mux = bridge_app.MuxBridge({0: _channel(0)[1], 2: _channel(2)[1]})
    lines = mux.handle_line(encode_frame("@2", "RAW", 3))
    assert len(lines) == 4
    assert all(bridge_proto.unframe(x)[0][0] == "@2" for x in lines)
    assert bridge_proto.unframe(lines[-1])[0] == ["@2", "END", "3"]
    assert mux.handle_line(encode_frame("@1", "ID")) == [
        encode_frame("@1", "ERR", 7, "no sensor on channel 1")
    ]
    assert mux.handle_line(encode_frame("@01", "ID")) == [
        encode_frame("ERR", 3, "bad channel address @01")
    ]
    assert mux.handle_line(encode_frame("CHANNELS")) == [
        encode_frame("CHANNELS", 2, 0, "SN-F0", 2, "SN-F2")
    ]


async def test_three_sensors_on_one_firmware_bridge_over_a_pty(board) -> None:  # type: ignore[no-untyped-def]
    chips, _mux, dev = board
    bridge = MultiplexedBridge(dev.path, VirtualClock(), timeout_s=2.0)
    try:
        assert await bridge.channels() == {0: "SN-F0", 1: "SN-F1", 2: "SN-F2"}
        handles = [bridge.channel(i) for i in range(3)]
        idents = [await h.identify() for h in handles]
        assert [(x.serial, x.channel, x.board_uid, x.partid) for x in idents] == [
            (f"SN-F{i}", i, UID, 0xED) for i in range(3)
        ]
        await handles[1].configure(4.0, 250.0)  # that chip only
        assert chips[1].range_g == 4.0 and chips[0].range_g == 2.0 and chips[2].range_g == 2.0
        acqs = await asyncio.gather(*(h.acquire(30) for h in handles))
        for i, acq in enumerate(acqs):
            np.testing.assert_allclose(acq.mean_g, TRUE_G[i], atol=1 / 64_000)
            assert acq.sensor_c == pytest.approx(DIE_C[i], abs=0.06)
        handles[2].mode = "raw"
        raw = await handles[2].acquire(5)
        np.testing.assert_allclose(raw.mean_g, TRUE_G[2], atol=1 / 64_000)
        with pytest.raises(ConfigurationFault, match="ERR 7 no sensor on channel 3"):
            await bridge.channel(3).identify()
        old_host = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=2.0)
        assert (await old_host.identify()).serial == "SN-F0"  # channel 0, unaddressed
        await old_host.close()
    finally:
        await bridge.close()
