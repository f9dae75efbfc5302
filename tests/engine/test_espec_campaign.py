"""A campaign on a rig whose chamber is an ESPEC P-300/SCP-220 (``chamber.driver =
"espec"``), its twin reached over the controller's ASCII protocol on loopback."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Campaign, Measurement
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner
from simulators.espec_sim import EspecController, EspecSetup, start_espec_server
from simulators.rig import start_sim_rig

from engine_helpers import SMALL_SPEC, SQLITE_ONLY, add_campaign, fake_calibrate  # isort: skip


def _espec_config(sim: Any, url: str) -> dict[str, Any]:
    return {"name": "lab",
            "chamber": {"driver": "espec", "url": url, "range_c": [-40, 85],
                        "max_rate_c_per_min": 5.0},
            "turntable": {"url": sim.table_url, "axes": 3},
            "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}


@pytest.mark.parametrize("ramp_c_per_min", [0.0, 5.0, 2.0])
@SQLITE_ONLY
async def test_a_campaign_steps_an_espec_chamber_and_refuses_a_ramp(sf, ramp_c_per_min: float  # type: ignore[no-untyped-def]
                                                                    ) -> None:
    clock = VirtualClock(idle_wall_s=0.0003)
    spec = {**SMALL_SPEC, "samples_per_position": 20, "ramp_c_per_min": ramp_c_per_min}
    cid = add_campaign(sf, spec, rig="lab")
    async with start_sim_rig(clock, seed=3) as sim:
        server = await start_espec_server(EspecController(sim.chamber, EspecSetup(
            mode="STANDBY")))
        try:
            async with open_rig(_espec_config(sim, server.url), clock) as devices:
                runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
                state = await asyncio.wait_for(runner.run(), 60.0)
        finally:
            await server.stop()
    with sf() as s:
        c = s.get(Campaign, cid)
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
        error = c.error
    if 0 < ramp_c_per_min < 5.0:  # slower than the chamber steps (its own 5 °C/min)
        assert state == "failed"
        assert "run the campaign with ramp_c_per_min = 0 (step) or ≥ 5" in error
        assert rows == []
        return
    assert state == "completed", error
    assert {(m.step, m.position) for m in rows} == {(st, p) for st in range(3) for p in range(6)}
    for m in rows:
        # The die reached each step: the setpoints went over the ESPEC protocol.
        assert abs(m.sensor_c - spec["setpoints_c"][m.step]) < 3.0
