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
    chip.ids = (0xAD, 0x1D, 0xEC, 0x01)
    chip.reset()
    assert main(["sensor", "id", path]) == 1
    assert "FAIL:" in capsys.readouterr().out


def test_nothing_on_the_port(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sensor", "id", "/dev/does-not-exist", "--timeout", "0.2"]) == 1
    assert "cannot open /dev/does-not-exist" in capsys.readouterr().out
