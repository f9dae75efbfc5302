"""Start-of-campaign sensor identity check (service/engine/identity.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.faults import ConfigurationFault
from drivers.protocols import SensorIdentity
from drivers.sensor_bridge import SerialAccelerometer
from service.engine.identity import (
    SensorMismatch,
    SerialBinding,
    binding_for_rig,
    check_identity,
    verify_sensor,
)
from simulators.bridge_sim import BridgeDevice, start_bridge_server
from simulators.truth import SensorTruth

UID = "E6614104035F2B2F"
GOOD = SensorIdentity("ADXL355", "SN-0001", "soakcal-fw-2.0", UID, 0xAD, 0x1D, 0xED, 0x01, "v2")


def test_eeprom_serial_must_match_and_both_are_named() -> None:
    ok = check_identity(GOOD, "SN-0001", SerialBinding("eeprom"))
    assert (ok.serial, ok.bound_by) == ("SN-0001", "eeprom")
    with pytest.raises(SensorMismatch, match="campaign names sensor SN-0004 but SN-0001 is "
                                             "connected") as err:
        check_identity(GOOD, "SN-0004", SerialBinding("eeprom"))
    assert not err.value.retryable and isinstance(err.value, ConfigurationFault)


def test_scanned_case_and_blanks_do_not_matter() -> None:
    assert check_identity(GOOD, "  sn-0001\n", SerialBinding()).serial == "sn-0001"


def test_rig_table_binds_board_uid_to_serial() -> None:
    blank = dataclasses.replace(GOOD, serial="")
    table = SerialBinding("table", {UID: "SN-K9"})
    assert check_identity(blank, "SN-K9", table).bound_by == "table"
    with pytest.raises(SensorMismatch, match="names sensor SN-L1 but SN-K9"):
        check_identity(blank, "SN-L1", table)
    with pytest.raises(SensorMismatch, match="not in the rig's 'serials' table"):
        check_identity(dataclasses.replace(blank, board_uid="0000"), "SN-K9", table)
    # auto: no EEPROM serial → the table decides
    assert check_identity(blank, "SN-K9", SerialBinding("auto", {UID: "SN-K9"})).bound_by == \
        "table"
    with pytest.raises(SensorMismatch, match="EEPROM blank"):
        check_identity(blank, "SN-K9", SerialBinding("eeprom"))


def test_wrong_part_or_no_sensor_fails_whatever_the_binding() -> None:
    adxl357 = dataclasses.replace(GOOD, partid=0xED - 1)
    with pytest.raises(SensorMismatch, match="part ids AD 1D EC"):
        check_identity(adxl357, "SN-0001", SerialBinding("any"))
    unwired = dataclasses.replace(GOOD, devid_ad=0, devid_mst=0, partid=0)
    with pytest.raises(SensorMismatch, match="check wiring"):
        check_identity(unwired, "SN-0001", SerialBinding("any"))


def test_any_accepts_every_serial_and_records_what_was_reported() -> None:
    v = check_identity(GOOD, "SN-K9", SerialBinding("any"))
    d = v.as_dict()
    assert (d["serial"], d["bound_by"], d["reported_serial"]) == ("SN-K9", "any", "SN-0001")
    assert d["reported_partid"] == "0xED" and d["reported_board_uid"] == UID
    v1 = SensorIdentity("ADXL355", "", "old", protocol="v1")  # v1 bridge: no ids to check
    assert check_identity(v1, "SN-1", SerialBinding("any")).as_dict()["reported_partid"] is None
    with pytest.raises(SensorMismatch, match="no board uid"):
        check_identity(v1, "SN-1", SerialBinding("table", {UID: "SN-1"}))
    with pytest.raises(SensorMismatch, match="names no sensor serial"):
        check_identity(GOOD, " ", SerialBinding("any"))
    with pytest.raises(ValueError):
        SerialBinding("scan")  # type: ignore[arg-type]


def test_binding_for_rig() -> None:
    assert binding_for_rig({"chamber": {"driver": "sim"}}).mode == "any"
    rig = {"chamber": {"driver": "modbus"},
           "sensors": [{"url": "/dev/ttyACM0", "serial_binding": "table",
                        "serials": {UID: "SN-9"}}]}
    b = binding_for_rig(rig)
    assert (b.mode, dict(b.table)) == ("table", {UID: "SN-9"})
    with pytest.raises(ValueError, match=r"sensors\[0\].serial_binding"):
        binding_for_rig({"chamber": {"driver": "modbus"},
                         "sensors": [{"url": "x", "serial_binding": "scan"}]})


async def test_verify_sensor_through_the_real_driver_and_simulated_bridge() -> None:
    """Five typed serials against one connected sensor: only its own passes."""
    clock = VirtualClock()
    truth = SensorTruth.adxl355_typical(seed=3)
    device = BridgeDevice(truth, clock, np.random.default_rng(0), lambda: 25.0,
                          lambda: (0.0, 0.0, 0.0))
    server = await start_bridge_server(device)
    accel = SerialAccelerometer(server.url, clock, timeout_s=0.5)
    try:
        ok = await verify_sensor(accel, truth.serial, SerialBinding("eeprom"))
        assert ok.identity.partid == 0xED and ok.bound_by == "eeprom"
        for typo in ("SN-0004", "SN-0005", "SN-K9", "SN-L1"):
            with pytest.raises(SensorMismatch, match=f"names sensor {typo} but {truth.serial}"):
                await verify_sensor(accel, typo, SerialBinding("eeprom"))
        # The sim twin's binding accepts them all (it mounts the sensor named).
        assert (await verify_sensor(accel, "SN-K9", SerialBinding("any"))).serial == "SN-K9"
    finally:
        await accel.close()
        await server.stop()


async def test_a_mismatch_fails_the_campaign_at_once_through_the_guard() -> None:
    """The engine's DeviceGuard neither retries nor suspends on a SensorMismatch."""
    from service.engine.guard import CampaignFailed, DeviceGuard, FaultPolicy

    clock = VirtualClock()
    suspended: list[str] = []
    guard = DeviceGuard(clock, FaultPolicy(), suspended.append, lambda: None)
    calls = []

    async def check() -> object:
        calls.append(1)
        return check_identity(GOOD, "SN-0004", SerialBinding("eeprom"))

    with pytest.raises(CampaignFailed, match="SN-0004 but SN-0001"):
        await guard.call("verify sensor", check)
    assert (len(calls), suspended, guard.faults_retried, clock.now()) == (1, [], 0, 0.0)
