"""``soakcal sim --serial``: the simulated bridge on a pseudo-terminal, opened by the same
serial driver a real USB-serial bridge is (pyserial on a device path)."""

from __future__ import annotations

import os
import sys

import pytest

from drivers.clock import RealClock, VirtualClock
from drivers.sensor_bridge import SerialAccelerometer
from simulators.pty_link import open_pty_link
from simulators.rig import start_sim_rig

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty") or sys.platform == "win32",
                                reason="pseudo-terminals need POSIX")


async def test_the_bridge_answers_on_a_pseudo_terminal() -> None:
    async with start_sim_rig(VirtualClock(), seed=4) as sim:
        link = await open_pty_link(sim.bridge_server.host, sim.bridge_server.port)
        try:
            assert link.path.startswith("/dev/")
            accel = SerialAccelerometer(link.path, RealClock())
            try:
                ident = await accel.identify()
                got = await accel.acquire(8)
            finally:
                await accel.close()
            # The reader can close the port and open it again: the link stays up.
            again = SerialAccelerometer(link.path, RealClock())
            try:
                assert (await again.identify()).serial == ident.serial
            finally:
                await again.close()
        finally:
            await link.close()
    assert ident.model == "ADXL355"
    assert got.n == 8
    assert 0.9 < sum(v * v for v in got.mean_g) ** 0.5 < 1.1  # a static sensor reads ~1 g


def test_soakcal_sim_serial_prints_the_pseudo_terminal(capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    from simulators.cli import run_sim

    assert run_sim(["--serial", "--duration-s", "0.2"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if "pseudo-terminal" in x)
    assert line.split()[2].startswith("/dev/")
