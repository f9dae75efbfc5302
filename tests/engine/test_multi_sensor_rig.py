"""The sim twin mounts as many sensors as a campaign names, each its own part (issue 12)."""

from __future__ import annotations

import numpy as np

from drivers.clock import VirtualClock
from service.engine.identity import verify_sensor
from service.engine.rigs import open_rig
from simulators.rig import sensor_seed

SIM = {"name": "sim", "chamber": {"driver": "sim"}}


async def _biases_g(serials: list[str], seed: int) -> dict[str, np.ndarray]:
    """Mean reading of every mounted sensor in one orientation (z up)."""
    clock = VirtualClock()
    out: dict[str, np.ndarray] = {}
    async with open_rig(SIM, clock, seed=seed, serials=serials,
                        sim_options={"modbus_in_memory": True}) as dev:
        assert list(dev.accelerometers) == serials
        assert dev.accelerometer is dev.accelerometers[serials[0]]
        for serial, accel in dev.accelerometers.items():
            verified = await verify_sensor(accel, serial, dev.serial_binding)
            assert verified.identity.serial == serial  # each bridge reports its own part
            await accel.configure(2.0, 62.5)
            out[serial] = np.asarray((await accel.acquire(400)).mean_g)
    return out


async def test_each_serial_is_its_own_part_in_every_run() -> None:
    serials = ["SN-A1", "SN-A2", "SN-A3"]
    first = await _biases_g(serials, seed=1)
    # Different parts: offsets of ±25 mg differ far beyond the 400-sample noise (~1 µg·√Hz).
    for a in serials:
        for b in serials:
            if a != b:
                assert np.max(np.abs(first[a] - first[b])) > 1e-3
    # The part is its serial's: another campaign (seed), another fixture order, same truth.
    again = await _biases_g(["SN-A3", "SN-A1"], seed=7)
    for serial in again:
        assert np.max(np.abs(again[serial] - first[serial])) < 2e-4
    assert sensor_seed("SN-A1") == sensor_seed("SN-A1") != sensor_seed("SN-A2")


async def test_one_serial_is_the_one_sensor_rig_as_before() -> None:
    clock = VirtualClock()
    async with open_rig(SIM, clock, seed=3, serials=["SN-1"],
                        sim_options={"modbus_in_memory": True}) as dev:
        assert dev.accelerometers == {}
