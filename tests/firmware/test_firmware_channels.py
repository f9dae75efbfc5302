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
from simulators import adxl355_regs
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
        # read together: one group command for the three, not three captures in turn
        group = encode_frame("AVG", 30, "@0", "@1", "@2")  # channel 1 at 250 Hz joins too
        assert [x for x in dev.received if b"AVG" in x] == [group]
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


class ReadLog:
    """Records which chip each data read goes to (an SPI transfer touching XDATA3)."""

    def __init__(self) -> None:
        self.reads: list[int] = []

    def watch(self, ch: int, chip: ADXL355Registers) -> None:
        transfer = chip.transfer

        def logged(tx: bytes) -> bytes:
            if tx and tx[0] == (adxl355_regs.TEMP2 << 1) | 1:  # the burst read of one sample
                self.reads.append(ch)
            return transfer(tx)

        chip.transfer = logged  # type: ignore[method-assign]


def _fields(line: bytes) -> list[str]:
    parsed = bridge_proto.unframe(line)
    assert parsed is not None
    return parsed[0]


def test_a_group_capture_reads_each_chip_in_turn_per_sample_period() -> None:
    parts = {i: _channel(i) for i in range(3)}
    log = ReadLog()
    for i, (chip, _b) in parts.items():
        log.watch(i, chip)
    mux = bridge_app.MuxBridge({i: b for i, (_c, b) in parts.items()})
    lines = mux.handle_line(encode_frame("AVG", 4, "@2", "@0", "@1"))
    # one sample period at a time, every chip in the command's order
    assert log.reads == [2, 0, 1] * 4
    # one line per channel, in the command's order, then END; each exactly the line a
    # capture of that channel alone gives (the same Averager) on an identical chip
    assert [_fields(x)[0] for x in lines] == ["@2", "@0", "@1", "END"]
    assert _fields(lines[-1]) == ["END", "AVG", "3"]
    for line in lines[:3]:
        ch = int(_fields(line)[0][1:])
        alone = bridge_app.MuxBridge({ch: _channel(ch)[1]})
        assert [line] == alone.handle_line(encode_frame(f"@{ch}", "AVG", 4))


def test_a_stalled_chip_and_an_empty_channel_get_their_own_err_lines() -> None:
    parts = {i: _channel(i) for i in range(3)}
    parts[1][0].regs[adxl355_regs.POWER_CTL] |= 0x01  # standby: DATA_RDY never comes
    mux = bridge_app.MuxBridge({i: b for i, (_c, b) in parts.items()})
    lines = [_fields(x) for x in mux.handle_line(encode_frame("AVG", 6, "@0", "@1", "@5", "@2"))]
    assert lines[1] == ["@1", "ERR", "5", "sensor not ready (no DATA_RDY)"]
    assert lines[2] == ["@5", "ERR", "7", "no sensor on channel 5"]
    assert [x[:3] for x in (lines[0], lines[3])] == [["@0", "AVG", "6"], ["@2", "AVG", "6"]]
    assert lines[4] == ["END", "AVG", "4"]
    assert parts[0][0].conversions == 6 and parts[2][0].conversions == 6


@pytest.mark.parametrize(
    "fields,why",
    [
        (["AVG", 0, "@0", "@1"], "n must be 1..100000"),
        (["AVG", 5, "@0", "@0"], "bad or repeated channel address @0"),
        (["AVG", 5, "@0", "@01"], "bad or repeated channel address @01"),
        (["AVG", 5, "@0", "ID"], "bad or repeated channel address ID"),
    ],
)
def test_a_bad_group_command_is_one_unaddressed_err_3(fields: list[object], why: str) -> None:
    mux = bridge_app.MuxBridge({0: _channel(0)[1], 1: _channel(1)[1]})
    assert mux.handle_line(encode_frame(*fields)) == [encode_frame("ERR", 3, why)]


def test_a_one_sensor_bridge_refuses_the_group_command_as_unknown() -> None:
    """What the host's fallback hears from a bridge without it: ERR 1, unaddressed."""
    _chip, single = _channel(0)
    assert single.handle_line(encode_frame("AVG", 5, "@0", "@1")) == [
        encode_frame("ERR", 1, "unknown command AVG")
    ]


def test_the_group_capture_bytes_of_docs_sensor_bridge_md() -> None:
    mux = bridge_app.MuxBridge({i: _channel(i)[1] for i in range(3)})
    assert encode_frame("AVG", 200, "@0", "@1", "@2") == b"$AVG,200,@0,@1,@2*A91B\r\n"
    assert mux.handle_line(b"$AVG,200,@0,@1,@2*A91B\r\n") == [
        b"$@0,AVG,200,3149.000,-11674.000,252826.000,0.000,0.000,0.000,2224.00,2224,2224,0"
        b"*F318\r\n",
        b"$@1,AVG,200,-128000.000,64000.000,204800.000,0.000,0.000,0.000,2111.00,2111,2111,0"
        b"*EF49\r\n",
        b"$@2,AVG,200,179200.000,0.000,-179200.000,0.000,0.000,0.000,1749.00,1749,1749,0*B872\r\n",
        b"$END,AVG,3*4E7A\r\n",
    ]
