"""The sim twin mounts as many sensors as a campaign names, each its own part (issue 12)."""

from __future__ import annotations

import numpy as np
import pytest

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


async def _biases_with_truths(serials: list[str], truths: dict) -> dict[str, np.ndarray]:
    clock = VirtualClock()
    out: dict[str, np.ndarray] = {}
    async with open_rig(SIM, clock, seed=5, serials=serials,
                        sim_options={"modbus_in_memory": True, "truths": truths}) as dev:
        for serial, accel in dev.accelerometers.items():
            await accel.configure(2.0, 62.5)
            out[serial] = np.asarray((await accel.acquire(400)).mean_g)
    return out


async def test_an_injected_truth_replaces_only_the_part_of_its_serial() -> None:
    from simulators.truth import SensorTruth

    serials = ["SN-B1", "SN-B2", "SN-B3"]
    own = await _biases_g(serials, seed=5)
    # SN-B1 (the first bridge) mounts SN-B3's part, SN-B2 SN-B1's; SN-B3 keeps its own.
    truths = {"SN-B1": SensorTruth.adxl355_typical(sensor_seed("SN-B3"), serial="SN-B1"),
              "SN-B2": SensorTruth.adxl355_typical(sensor_seed("SN-B1"), serial="SN-B2")}
    got = await _biases_with_truths(serials, truths)
    # Same part: equal within the 400-sample noise; another part: ±25 mg offsets apart.
    assert np.max(np.abs(got["SN-B1"] - own["SN-B3"])) < 2e-4
    assert np.max(np.abs(got["SN-B2"] - own["SN-B1"])) < 2e-4
    assert np.max(np.abs(got["SN-B3"] - own["SN-B3"])) < 2e-4
    assert np.max(np.abs(got["SN-B1"] - own["SN-B1"])) > 1e-3


async def test_a_truth_for_a_serial_not_mounted_is_refused() -> None:
    from simulators.truth import SensorTruth

    clock = VirtualClock()
    with pytest.raises(ValueError, match="SN-X9"):
        async with open_rig(SIM, clock, seed=1, serials=["SN-C1", "SN-C2"],
                            sim_options={"truths": {"SN-X9": SensorTruth.adxl355_typical(1)}}):
            pass
