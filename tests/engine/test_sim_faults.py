"""5 % of Modbus requests failing must not fail or corrupt a campaign (through the twin).

The chamber and table servers of the twin drop connections, swallow replies
and answer DEVICE_BUSY on 5 % of requests (seeded); the real drivers, the
engine and the database run unchanged. The same campaign without faults is
the reference: every stored reading must match it within noise.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace
from typing import Any

import numpy as np
from engine_helpers import SMALL_SPEC, SQLITE_ONLY, add_campaign, fake_calibrate
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Measurement
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner
from simulators.faults import SimFaults
from simulators.rig import RigFaults, start_sim_rig

SPEC = {**SMALL_SPEC, "positions": "six", "samples_per_position": 20}
N_STEPS, N_POS = len(SPEC["setpoints_c"]), 6


def _five_percent() -> SimFaults:
    return SimFaults(p_exception=0.025, p_no_reply=0.01, p_drop=0.015)


async def _run(sf: Any, faults: RigFaults | None) -> tuple[str, dict[tuple[int, int], Any], dict]:
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = add_campaign(sf, SPEC, rig="lab")
    async with start_sim_rig(clock, seed=11, faults=faults) as sim:
        cfg = {"name": "lab",
               "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": sim.chamber_map},
               "turntable": {"url": sim.table_url},
               # the twin reached by URL reports its own serial: bind any (as the sim rig does)
               "sensors": [{"url": sim.sensor_url, "serial_binding": "any"}]}
        async with open_rig(cfg, clock) as devices:
            # A swallowed reply costs the link's wall-time timeout (1 s shipped: a socket
            # guard, not physics); loopback replies take milliseconds, so 0.3 s keeps the
            # faults' handling the same at a third of the test's wall time.
            for link in (devices.chamber.link, devices.turntable.link):
                link.policy = replace(link.policy, timeout_s=0.3)
            runner = CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate)
            state = await asyncio.wait_for(runner.run(), 90.0)
            stats = {"chamber": dict(devices.chamber.link.stats),
                     "table": dict(devices.turntable.link.stats),
                     "engine_retried": runner.guard.faults_retried}
    with sf() as s:
        rows = s.execute(select(Measurement).where(Measurement.campaign_id == cid)).scalars().all()
        by_key: dict[tuple[int, int], Any] = {}
        for m in rows:
            assert (m.step, m.position) not in by_key, f"taken twice: {(m.step, m.position)}"
            by_key[(m.step, m.position)] = m
    return state, by_key, stats


@SQLITE_ONLY  # the Modbus link and the engine's guard are under test, not the store
async def test_five_percent_modbus_faults_neither_fail_nor_corrupt(sf) -> None:  # type: ignore[no-untyped-def]
    clean_state, clean, _ = await _run(sf, None)
    state, faulty, stats = await _run(
        sf, RigFaults(chamber=_five_percent(), table=_five_percent()))

    assert clean_state == state == "completed"
    assert set(faulty) == set(clean) == {(s, p) for s in range(N_STEPS) for p in range(N_POS)}
    # Faults really happened and were absorbed by retries and reconnects. The link retries
    # each read and idempotent write itself (drivers/modbus_link.py); only what outlasts its
    # three tries (0.05³ per request) and a lost reply to the table's move command (not
    # repeated: 2.5 % of about 18 moves) reach the engine's guard, about one call a campaign.
    retries = stats["chamber"]["retries"] + stats["table"]["retries"]
    requests = stats["chamber"]["requests"] + stats["table"]["requests"]
    assert retries >= 5, stats
    assert stats["chamber"]["reconnects"] + stats["table"]["reconnects"] >= 1, stats
    assert 0.02 < retries / requests < 0.10, stats
    assert stats["engine_retried"] <= 5, stats
    for key, m in faulty.items():
        ref = clean[key]
        assert (m.ref_x, m.ref_y, m.ref_z) == (ref.ref_x, ref.ref_y, ref.ref_z)
        raw, raw_ref = np.array([m.ax, m.ay, m.az]), np.array([ref.ax, ref.ay, ref.az])
        # Same position, same step: equal within noise (σ of a 20-sample mean ≈ 30 µg) and the
        # die's small timing difference; a wrong position would be off by ~1 g.
        assert np.abs(raw - raw_ref).max() < 0.5e-3, (key, raw - raw_ref)
        assert abs(m.sensor_c - ref.sensor_c) < 0.5
        assert m.n == ref.n == SPEC["samples_per_position"]
