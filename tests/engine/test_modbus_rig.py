"""A rig configured by URL (`chamber.driver = "modbus"`): the path a real lab's rig takes.

The devices are the twin's servers on loopback, reached only through the URLs
of the rig config, as docker-compose's `sim-rig` container is reached by the
service; so this is the same configuration without Docker.
"""

from __future__ import annotations

import asyncio
from collections import Counter
from typing import Any

import numpy as np
import pytest
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Campaign, Measurement
from service.engine.rigs import RigConfigError, open_rig, rig_config_errors, rig_time_scale
from service.engine.runner import CampaignRunner
from simulators.rig import start_sim_rig

from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate  # isort: skip


def _modbus_config(sim: Any, chamber_map: str, binding: str = "any") -> dict[str, Any]:
    return {
        "name": "lab",
        "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": chamber_map,
                    "device_id": 1, "range_c": [-70, 180]},
        "turntable": {"url": sim.table_url, "axes": 3},
        "sensors": [{"url": sim.sensor_url, "serial_binding": binding}],
    }


async def test_the_wrong_sensor_fails_the_campaign_at_start_with_both_serials(sf) -> None:  # type: ignore[no-untyped-def]
    """A rig that binds serials by fixture EEPROM: the campaign names SN-T, SN-OTHER is there."""
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SMALL_SPEC, "positions": "six"}, rig="lab")
    async with start_sim_rig(clock, seed=3) as sim:
        sim.bridge.eeprom_serial = "SN-OTHER"
        async with open_rig(_modbus_config(sim, "eurotherm3216", "eeprom"), clock) as devices:
            fake = fake_calibrate
            state = await asyncio.wait_for(
                CampaignRunner(sf, cid, devices, clock, calibrate=fake).run(), 60.0)
    assert state == "failed"
    with sf() as s:
        c = s.get(Campaign, cid)
        assert "SN-T" in c.error and "SN-OTHER" in c.error, c.error
        assert s.execute(select(Measurement).where(Measurement.campaign_id == cid)).first() \
            is None


async def test_the_right_sensor_is_stored_with_its_identity(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, {**SMALL_SPEC, "positions": "six", "samples_per_position": 20},
                       rig="lab")
    provenance: dict[str, Any] = {}

    def calibrate(cols: Any, prov: dict[str, Any]) -> Any:
        provenance.update(prov)
        return fake_calibrate(cols, prov)

    async with start_sim_rig(clock, seed=3) as sim:
        sim.bridge.eeprom_serial = "sn-t"  # case is not part of a serial
        async with open_rig(_modbus_config(sim, "eurotherm3216", "eeprom"), clock) as devices:
            state = await asyncio.wait_for(
                CampaignRunner(sf, cid, devices, clock, calibrate=calibrate).run(), 60.0)
    assert state == "completed"
    ident = provenance["sensor_identity"]
    assert ident["serial"] == "SN-T" and ident["bound_by"] == "eeprom"


@pytest.mark.parametrize("chamber_map", ["eurotherm3216", "watlow_f4t"])
async def test_campaign_on_a_rig_reached_by_url(sf, chamber_map: str) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    spec = {**SMALL_SPEC, "positions": "six", "samples_per_position": 20}
    cid = add_campaign(sf, spec, rig="lab")
    async with start_sim_rig(clock, seed=3, chamber_map=chamber_map) as sim:
        cfg = _modbus_config(sim, chamber_map)
        async with open_rig(cfg, clock) as devices:
            runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
            state = await asyncio.wait_for(runner.run(), 60.0)
    assert state == "completed"
    with sf() as s:
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
    counts = Counter((m.step, m.position) for m in rows)
    assert set(counts) == {(st, p) for st in range(3) for p in range(6)}
    assert max(counts.values()) == 1
    for m in rows:
        # The sensor saw gravity where the table was told to put it (through the wire).
        raw, ref = np.array([m.ax, m.ay, m.az]), np.array([m.ref_x, m.ref_y, m.ref_z])
        assert float(np.dot(raw / np.linalg.norm(raw), ref)) > 0.99
        # The die reached each step: the chamber obeyed setpoints sent in this map's encoding.
        assert abs(m.sensor_c - spec["setpoints_c"][m.step]) < 3.0


def test_config_errors_name_the_field() -> None:
    errors = dict(rig_config_errors(
        {"driver": "modbus", "url": "http://x", "map": "nope", "time_scale": 0},
        {"url": "tcp://h:502", "axes": 5, "device_id": 300},
        [],
    ))
    assert set(errors) == {"chamber.url", "chamber.map", "chamber.time_scale",
                           "turntable.axes", "turntable.device_id", "sensors[0].url"}
    assert rig_config_errors({"driver": "sim", "range_c": [-40, 85]}, {}, []) == []
    assert dict(rig_config_errors({"driver": "serial?"}, {}, [])).keys() == {"chamber.driver"}


def test_time_scale_is_the_rigs_own() -> None:
    assert rig_time_scale({"chamber": {"driver": "sim"}}) is None
    assert rig_time_scale({"chamber": {"driver": "modbus"}}) == 1.0
    assert rig_time_scale({"chamber": {"driver": "modbus", "time_scale": 600}}) == 600.0


async def test_a_bad_config_is_refused_before_touching_a_device() -> None:
    with pytest.raises(RigConfigError, match="chamber.url"):
        async with open_rig({"name": "x", "chamber": {"driver": "modbus"},
                             "turntable": {"url": "tcp://127.0.0.1:1"},
                             "sensors": [{"url": "socket://127.0.0.1:1"}]}, VirtualClock()):
            pass


def test_a_real_chamber_with_a_hand_placed_fixture_is_a_valid_rig() -> None:
    """The small lab: a Eurotherm over Modbus, no turntable (the operator places the cube)."""
    chamber = {"driver": "modbus", "url": "tcp://10.0.0.5:502", "map": "eurotherm-3216"}
    sensors = [{"url": "/dev/ttyACM0"}]
    assert rig_config_errors(chamber, {"driver": "manual"}, sensors) == []
    # without the manual marker the same rig lacks its table
    assert ("turntable.url" in {p for p, _ in rig_config_errors(chamber, {}, sensors)})


async def test_a_modbus_chamber_with_a_manual_table_opens_with_the_operator_as_table(sf) -> None:  # type: ignore[no-untyped-def]
    from drivers.manual_table import ManualTurntable

    clock = VirtualClock(idle_wall_s=0.0003)
    async with start_sim_rig(clock, seed=3) as sim:
        cfg = {**_modbus_config(sim, "eurotherm3216"), "turntable": {"driver": "manual"}}
        async with open_rig(cfg, clock) as devices:
            assert isinstance(devices.turntable, ManualTurntable)
            status = await devices.chamber.read_status()
            assert -70.0 < status.process_c < 180.0


SEVERAL = ["SN-R1", "SN-R2", "SN-R3"]


def _several_config(sim: Any) -> dict[str, Any]:
    """One bridge per sensor: each entry its own port, declaring the sensor it carries."""
    cfg = _modbus_config(sim, "eurotherm3216")
    cfg["sensors"] = [{"url": s.url, "serial": s.serial, "serial_binding": "eeprom"}
                      for s in reversed(sim.sensors)]  # entry order is not campaign order
    return cfg


async def test_a_several_sensor_campaign_runs_on_a_rig_reached_by_url(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    spec = {**SMALL_SPEC, "setpoints_c": [20.0], "positions": "six", "samples_per_position": 20,
            "sensors": SEVERAL}
    cid = add_campaign(sf, spec, rig="lab")
    with sf() as s:
        s.get(Campaign, cid).sensor = SEVERAL[0]
        s.commit()
    async with start_sim_rig(clock, seed=3, serials=SEVERAL) as sim:
        sim.sensors[1].bridge.eeprom_serial = "SN-OTHER"  # the wrong part on SN-R2's port
        async with open_rig(_several_config(sim), clock, serials=SEVERAL) as devices:
            assert list(devices.accelerometers) == SEVERAL
            runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
            state = await asyncio.wait_for(runner.run(), 60.0)
    assert state == "completed"
    with sf() as s:
        camp = s.get(Campaign, cid)
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
    # each port's identity checked by its own entry: the wrong part is dropped, naming both
    assert set(camp.sensors_dropped) == {"SN-R2"}
    assert "SN-OTHER" in camp.sensors_dropped["SN-R2"]
    assert Counter(m.sensor for m in rows) == {"SN-R1": 6, "SN-R3": 6}
    by_sensor = {(m.sensor, m.position): m.ax for m in rows}
    assert by_sensor[("SN-R1", 0)] != by_sensor[("SN-R3", 0)]  # two parts, two ports


async def test_a_sensor_no_entry_declares_or_two_behind_one_bridge_is_refused() -> None:
    clock = VirtualClock(idle_wall_s=0.0003)
    async with start_sim_rig(clock, seed=3, serials=SEVERAL) as sim:
        cfg = _several_config(sim)
        with pytest.raises(RigConfigError, match="'SN-NONE' is not mounted"):
            async with open_rig(cfg, clock, serials=["SN-R1", "SN-NONE"]):
                pass
        cfg["sensors"][0]["serials"] = {"UID-A": "SN-R1"}  # SN-R3's port claims SN-R1 too
        del cfg["sensors"][2]
        with pytest.raises(RigConfigError, match="one bridge per sensor"):
            async with open_rig(cfg, clock, serials=["SN-R3", "SN-R1"]):
                pass


def test_every_sensor_entry_is_validated_and_a_serial_is_declared_once() -> None:
    chamber = {"driver": "modbus", "url": "tcp://h:502"}
    table = {"url": "tcp://h:503"}
    errors = dict(rig_config_errors(chamber, table, [
        {"url": "/dev/ttyUSB0", "serial": "SN-1"},
        {"url": "/dev/ttyUSB1", "serial": "SN-1", "framing": "v9"},
        {"url": "/dev/ttyUSB2", "serial": 7}]))
    assert set(errors) == {"sensors[1].serial", "sensors[1].framing", "sensors[2].serial"}
    assert "sensors[0]" in errors["sensors[1].serial"]
