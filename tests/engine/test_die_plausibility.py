"""A chamber read with the wrong scale never gets a measurement stored under its labels.

The twin's controller is set to whole degrees while the lab's map assumes one decimal
place (a common Eurotherm 3216 set-up): the engine's setpoint 2 °C is written as 20
counts, the air goes to 20 °C and the PV reads 2.0 °C, in band. Only the sensors' dies
tell: the campaign fails at the first capture, naming both temperatures, and stores
nothing (DESIGN: plausibility at the boundaries).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from engine_helpers import SMALL_SPEC, SQLITE_ONLY, add_campaign, fake_calibrate
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Measurement
from service.engine import store
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner
from simulators.chamber_sim import ControllerSetup
from simulators.rig import start_sim_rig

INT16_MAP = Path(__file__).parents[1] / "drivers" / "data" / "eurotherm-3216-int16.toml"
SPEC: dict[str, Any] = {**SMALL_SPEC, "setpoints_c": [2.0, 4.0], "positions": "six",
                        "samples_per_position": 20}


@SQLITE_ONLY
async def test_a_chamber_read_x10_off_fails_before_storing_a_capture(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with start_sim_rig(clock, seed=5, chamber_map=str(INT16_MAP),
                             controller=ControllerSetup(decimals=0)) as sim:
        cfg = {"name": "lab",
               "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": str(INT16_MAP)},
               "turntable": {"url": sim.table_url},
               "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}
        async with open_rig(cfg, clock) as devices:
            runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
            assert await asyncio.wait_for(runner.run(), 120) == "failed"
    error = store.load_campaign(sf, cid).error or ""
    assert "the chamber reads 2.0 °C while the sensors' dies read" in error
    assert "not approaching it" in error
    assert "decimal places" in error and "rig check" in error
    with sf() as s:
        assert s.execute(select(Measurement.id).where(Measurement.campaign_id == cid)).all() == []
