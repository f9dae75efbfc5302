"""A bridge still on the v1 firmware: what a host on each framing sees."""

from __future__ import annotations

import pytest
from pty_device import PtyDevice

from drivers.bridge_protocol import encode_frame, parse_frame
from drivers.clock import VirtualClock
from drivers.faults import ProtocolError
from drivers.sensor_bridge import SerialAccelerometer


def v1_only_bridge(line: bytes) -> list[bytes]:
    """The v1 firmware's behaviour: XOR frames only, anything else is ERR 2 (in v1)."""
    try:
        frame = parse_frame(line)
    except ProtocolError:
        frame = None
    if frame is None or frame.framing != "v1":
        return [encode_frame("ERR", 2, "bad frame or checksum", framing="v1")]
    if frame.fields == ["ID"]:
        return [encode_frame("ID", "ADXL355", "SN-0007", "bridge-1.3", framing="v1")]
    return [encode_frame("ERR", 1, "unknown command", framing="v1")]


async def test_v2_host_gets_a_clear_hint_and_v1_host_works() -> None:
    dev = PtyDevice(on_line=v1_only_bridge)
    v2 = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0)
    v1 = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0, framing="v1")
    try:
        with pytest.raises(ProtocolError, match="v1 frame on a v2 link .*framing to v1"):
            await v2.identify()
        await v2.close()
        ident = await v1.identify()
        assert (ident.serial, ident.firmware, ident.board_uid, ident.partid) == (
            "SN-0007", "bridge-1.3", "", None)
    finally:
        await v1.close()
        dev.close()
