"""``soakcal sensor id|bind|read`` against the reference firmware on a pty."""

from __future__ import annotations

import json
from collections.abc import Iterator

import adxl355_spi
import bridge_app
import fixture_eeprom
import pytest
from pty_device import PtyDevice
from test_firmware import UID, MemI2C

from service.cli import main
from simulators.adxl355_regs import ADXL355Registers


@pytest.fixture
def port() -> Iterator[tuple[str, ADXL355Registers]]:
    chip = ADXL355Registers(lambda: (0.0, 0.5, -0.5), lambda: 40.0)
    bridge = bridge_app.Bridge(adxl355_spi.ADXL355(chip), UID,
                               fixture_eeprom.FixtureEeprom(MemI2C()))
    dev = PtyDevice(on_line=bridge.handle_line)
    yield dev.path, chip
    dev.close()


def test_id_bind_read(port: tuple[str, ADXL355Registers],
                      capsys: pytest.CaptureFixture[str]) -> None:
    path, chip = port
    assert main(["sensor", "id", path]) == 0
    out = capsys.readouterr().out
    assert "serial     (none: fixture EEPROM blank or absent)" in out and UID in out
    assert main(["sensor", "bind", path, "SN-0042"]) == 0
    assert f"bound SN-0042 to the fixture on bridge {UID}" in capsys.readouterr().out
    assert main(["sensor", "id", path, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert (d["serial"], d["partid"], d["ok"]) == ("SN-0042", "0xED", True)
    assert main(["sensor", "read", path, "-n", "20"]) == 0
    out = capsys.readouterr().out
    assert "(+0.000000, +0.500000, -0.500000) g over 20 samples" in out
    assert "sensor_c   40.0" in out and "°C" in out
    assert main(["sensor", "bind", path, "SN 42"]) == 2
    assert "must be 1..24 printable" in capsys.readouterr().err
    chip.ids = (0xAD, 0x1D, 0xEC, 0x01)
    chip.reset()
    assert main(["sensor", "id", path]) == 1
    assert "FAIL:" in capsys.readouterr().out


def test_nothing_on_the_port(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sensor", "id", "/dev/does-not-exist", "--timeout", "0.2"]) == 1
    assert "cannot open /dev/does-not-exist" in capsys.readouterr().err
    assert main(["sensor", "read", "/dev/x", "--protocol", "stream", "--columns", "x,y,z"]) == 2
    assert "--columns: expected the four names" in capsys.readouterr().err
    assert main(["sensor", "bind", "/dev/x", "SN-1", "--protocol", "stream"]) == 2
    assert main(["sensor", "read", "/dev/x", "-n", "0"]) == 2


def test_read_a_plain_stream(capsys: pytest.CaptureFixture[str]) -> None:
    lines = iter(lambda: b"t=30.0 x=0 y=-1000.0 z=0\r\n", None)
    dev = PtyDevice(stream=lambda: next(lines))
    try:
        assert main(["sensor", "read", dev.path, "--protocol", "stream", "--units", "mg",
                     "--columns", "t,x,y,z", "-n", "10"]) == 0
    finally:
        dev.close()
    out = capsys.readouterr().out
    assert "(+0.000000, -1.000000, +0.000000) g over 10 samples" in out
    assert "sensor_c   30.00 °C" in out


def test_a_channel_of_a_multiplexing_bridge(capsys: pytest.CaptureFixture[str]) -> None:
    chips = [ADXL355Registers(lambda: (0.0, 0.5, -0.5), lambda: 40.0),
             ADXL355Registers(lambda: (0.6, 0.0, 0.8), lambda: 10.0)]
    eeproms = [fixture_eeprom.FixtureEeprom(MemI2C()) for _ in chips]
    mux = bridge_app.MuxBridge({i: bridge_app.Bridge(adxl355_spi.ADXL355(c), UID, e)
                                for i, (c, e) in enumerate(zip(chips, eeproms, strict=True))})
    dev = PtyDevice(on_line=mux.handle_line)
    try:
        assert main(["sensor", "bind", dev.path, "SN-CH1", "--channel", "1"]) == 0
        assert (eeproms[0].read_serial(), eeproms[1].read_serial()) == ("", "SN-CH1")
        capsys.readouterr()
        assert main(["sensor", "id", dev.path, "--channel", "1", "--json"]) == 0
        d = json.loads(capsys.readouterr().out)
        assert (d["serial"], d["channel"], d["ok"]) == ("SN-CH1", 1, True)
        assert main(["sensor", "read", dev.path, "--channel", "1", "-n", "10"]) == 0
        assert "(+0.600000, +0.000000, +0.800000) g" in capsys.readouterr().out
        assert main(["sensor", "id", dev.path, "--channel", "2"]) == 1
        assert "ERR 7 no sensor on channel 2" in capsys.readouterr().err
        assert main(["sensor", "id", dev.path, "--channel", "100"]) == 2
        assert "--channel: expected 0..99" in capsys.readouterr().err
    finally:
        dev.close()
