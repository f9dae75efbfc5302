"""Several sensors behind one multiplexing bridge, through the engine (issue 12).

The twin mounts the sensors on one simulated bridge, a channel each
(``sim_options={"multiplexed": True}``); a ``modbus`` rig declares them in one sensor
entry's ``channels``. Either way the engine reads them over one port and drops a failing
channel alone.
"""

from __future__ import annotations

import asyncio
from collections import Counter
from typing import Any

import numpy as np
import pytest
from engine_helpers import SMALL_SPEC, add_campaign, fake_calibrate
from sqlalchemy import select

from drivers.clock import VirtualClock
from service.db.models import Calibration, Campaign, Measurement, SoakProbe
from service.engine.rigs import RigConfigError, open_rig, rig_config_errors, sensor_entries
from service.engine.runner import CampaignRunner
from simulators.faults import SimFaults
from simulators.rig import RigFaults, start_sim_rig
from simulators.truth import SensorTruth

SERIALS = ["SN-X0", "SN-X1", "SN-X2"]
# one short step: six positions of 20 samples each, after a 2-minute fixed soak
SPEC = {
    **SMALL_SPEC,
    "setpoints_c": [20.0],
    "soak_min": 2,
    "stability": "fixed",
    "samples_per_position": 20,
    "sensors": SERIALS,
}
SIM = {"name": "sim", "chamber": {"driver": "sim"}, "turntable": {}, "sensors": []}


def _campaign(sf, spec: dict[str, Any], rig: str = "sim") -> int:  # type: ignore[no-untyped-def]
    cid = add_campaign(sf, spec, rig=rig)
    with sf() as s:
        s.get(Campaign, cid).sensor = spec["sensors"][0]
        s.commit()
    return cid


def _rows(sf, cid: int) -> tuple[Any, list[Measurement], list[Calibration]]:  # type: ignore[no-untyped-def]
    with sf() as s:
        camp = s.get(Campaign, cid)
        rows = s.scalars(select(Measurement).where(Measurement.campaign_id == cid)).all()
        cals = s.scalars(select(Calibration).where(Calibration.campaign_id == cid)).all()
        s.expunge_all()
    return camp, list(rows), list(cals)


class DeadAxisTruth:
    """A part whose z axis reads nothing: |a| far below 1 g (an out-of-range reading)."""

    def __init__(self, serial: str) -> None:
        self._part = SensorTruth.adxl355_typical(7, serial=serial)
        self.serial = serial

    def __getattr__(self, name: str) -> Any:
        return getattr(self._part, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("_part", "serial"):
            object.__setattr__(self, name, value)
        else:
            setattr(self._part, name, value)

    def sample_g(
        self, ref_g: np.ndarray, die_c: float, n: int, rng: np.random.Generator, t_s: float = 0.0,
        lab_to_sensor: np.ndarray | None = None,
    ) -> np.ndarray:
        g = self._part.sample_g(ref_g, die_c, n, rng, t_s=t_s, lab_to_sensor=lab_to_sensor)
        return g * 0.1


async def _run_twin(
    sf,
    cid: int,
    sim_options: dict[str, Any],  # type: ignore[no-untyped-def]
    break_channel=None,
) -> str:
    clock = VirtualClock()
    async with open_rig(
        SIM,
        clock,
        seed=4,
        serials=SERIALS,
        sim_options={"multiplexed": True, "modbus_in_memory": True, **sim_options},
    ) as devices:
        if break_channel is not None:
            break_channel(devices)
        return await asyncio.wait_for(
            CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run(), 120.0
        )


async def test_three_sensors_on_one_multiplexed_twin_bridge_give_three_recordings(sf) -> None:  # type: ignore[no-untyped-def]
    cid = _campaign(sf, SPEC)
    seen: dict[str, Any] = {}

    def look(devices) -> None:  # type: ignore[no-untyped-def]
        seen.update({s: (a.url, a.channel) for s, a in devices.accelerometers.items()})

    assert await _run_twin(sf, cid, {}, look) == "completed"
    # one port, a channel per sensor in campaign order
    assert len({url for url, _ in seen.values()}) == 1
    assert [seen[s][1] for s in SERIALS] == [0, 1, 2]
    camp, rows, cals = _rows(sf, cid)
    assert Counter(m.sensor for m in rows) == {s: 6 for s in SERIALS}
    assert sorted(c.sensor for c in cals) == sorted(SERIALS)
    assert not camp.sensors_dropped
    # each channel is its own part: the same position reads differently on each
    ax = {m.sensor: m.ax for m in rows if m.position == 0}
    assert len({round(v, 4) for v in ax.values()}) == 3


async def test_a_silent_channel_is_dropped_and_the_others_complete(sf) -> None:  # type: ignore[no-untyped-def]
    cid = _campaign(sf, {**SPEC, "retry_backoff_s": 0.1})
    # The rig's sensor faults are channel 0's (the first serial's); the others answer.
    faults = RigFaults(sensor=SimFaults(p_no_reply=1.0))

    def short_wait(devices) -> None:  # type: ignore[no-untyped-def]
        # It never answers, so its wall timeout only sets the test's duration.
        devices.accelerometers["SN-X0"].timeout_s = 0.2

    assert await _run_twin(sf, cid, {"faults": faults}, short_wait) == "completed"
    camp, rows, cals = _rows(sf, cid)
    assert set(camp.sensors_dropped) == {"SN-X0"}
    assert "no answer after 4 tries" in camp.sensors_dropped["SN-X0"]
    assert Counter(m.sensor for m in rows) == {"SN-X1": 6, "SN-X2": 6}
    assert sorted(c.sensor for c in cals) == ["SN-X1", "SN-X2"]


async def test_an_out_of_range_channel_is_dropped_with_its_reason(sf) -> None:  # type: ignore[no-untyped-def]
    cid = _campaign(sf, SPEC)
    truths = {"SN-X2": DeadAxisTruth("SN-X2")}
    assert await _run_twin(sf, cid, {"truths": truths}) == "completed"
    camp, rows, _cals = _rows(sf, cid)
    assert set(camp.sensors_dropped) == {"SN-X2"}
    assert "reading out of range" in camp.sensors_dropped["SN-X2"]
    assert Counter(m.sensor for m in rows) == {"SN-X0": 6, "SN-X1": 6}


def _mux_config(url: str, chamber_url: str, table_url: str, **entry: Any) -> dict[str, Any]:
    return {
        "name": "lab",
        "chamber": {
            "driver": "modbus",
            "url": chamber_url,
            "map": "eurotherm3216",
            "range_c": [-70, 180],
        },
        "turntable": {"url": table_url, "axes": 3},
        "sensors": [
            {
                "url": url,
                "serial_binding": "eeprom",
                "channels": {str(i): s for i, s in enumerate(SERIALS)},
                **entry,
            }
        ],
    }


async def test_a_modbus_rig_declares_its_multiplexing_bridge_by_channels(sf) -> None:  # type: ignore[no-untyped-def]
    """Reached by URL like a real lab's rig; each channel's EEPROM serial is checked."""
    clock = VirtualClock(idle_wall_s=0.0003)
    cid = _campaign(sf, SPEC, rig="lab")
    async with start_sim_rig(
        clock, seed=3, serials=SERIALS, multiplexed=True, modbus_in_memory=False
    ) as sim:
        sim.sensors[1].bridge.eeprom_serial = "SN-OTHER"  # the wrong part on channel 1
        cfg = _mux_config(sim.sensor_url, sim.chamber_url, sim.table_url)
        assert rig_config_errors(cfg["chamber"], cfg["turntable"], cfg["sensors"]) == []
        async with open_rig(cfg, clock, serials=SERIALS) as devices:
            assert [a.channel for a in devices.accelerometers.values()] == [0, 1, 2]
            state = await asyncio.wait_for(
                CampaignRunner(sf, cid, devices, clock, calibrate=fake_calibrate).run(), 120.0
            )
    assert state == "completed"
    camp, rows, _cals = _rows(sf, cid)
    assert set(camp.sensors_dropped) == {"SN-X1"}
    assert "SN-OTHER" in camp.sensors_dropped["SN-X1"]
    assert "@1" in camp.sensors_dropped["SN-X1"]  # names the bridge's channel
    assert Counter(m.sensor for m in rows) == {"SN-X0": 6, "SN-X2": 6}


async def test_a_one_sensor_campaign_on_a_channel_uses_that_channel(sf) -> None:  # type: ignore[no-untyped-def]
    clock = VirtualClock(idle_wall_s=0.0003)
    async with start_sim_rig(clock, seed=3, serials=SERIALS, multiplexed=True) as sim:
        cfg = _mux_config(sim.sensor_url, sim.chamber_url, sim.table_url)
        async with open_rig(cfg, clock, serials=["SN-X2"]) as devices:
            assert devices.accelerometers == {}
            ident = await devices.accelerometer.identify()
            assert (ident.channel, ident.serial) == (2, "SN-X2")
            assert devices.serial_binding.mode == "eeprom"


def test_sensor_entries_resolve_channels_and_refuse_sharing_without_them() -> None:
    cfg = _mux_config("/dev/ttyACM0", "tcp://h:502", "tcp://h:503")
    cfg["sensors"].append({"url": "/dev/ttyACM1", "serial": "SN-Y"})
    assert sensor_entries(cfg, ["SN-X2", "SN-Y", "SN-X0"]) == {
        "SN-X2": (0, 2),
        "SN-Y": (1, None),
        "SN-X0": (0, 0),
    }
    cfg["sensors"][1]["serials"] = {"UID-1": "SN-Z"}
    with pytest.raises(RigConfigError, match="one bridge per sensor is needed, or declare"):
        sensor_entries(cfg, ["SN-Y", "SN-Z"])


def test_channel_config_problems_name_the_key() -> None:
    chamber, table = {"driver": "modbus", "url": "tcp://h:502"}, {"url": "tcp://h:503"}

    def errors(*sensors: dict[str, Any]) -> dict[str, str]:
        return dict(rig_config_errors(chamber, table, list(sensors)))

    ok = {"url": "/dev/ttyACM0", "channels": {"0": "SN-1", "1": "SN-2"}}
    assert errors(ok) == {}
    got = errors(
        {"url": "/dev/ttyACM0", "channels": {"0": "SN-1", "x": "SN-2", "2": "SN-1", "3": ""}}
    )
    assert set(got) == {"sensors[0].channels.x", "sensors[0].channels.2", "sensors[0].channels.3"}
    assert "already on channel 0" in got["sensors[0].channels.2"]
    assert set(errors({"url": "u", "channels": {}})) == {"sensors[0].channels"}
    assert set(errors({"url": "u", "channels": {"0": "SN-1"}, "framing": "v1"})) == {
        "sensors[0].channels"
    }
    assert set(
        errors(
            {"url": "u", "channels": {"0": "SN-1"}, "protocol": "stream", "serial_binding": "any"}
        )
    ) == {"sensors[0].channels"}
    assert set(errors({"url": "u", "channels": {"0": "SN-1"}, "serial": "SN-1"})) == {
        "sensors[0].serial"
    }
    assert (
        "on no channel"
        in errors({"url": "u", "channels": {"0": "SN-1"}, "serials": {"UID@1": "SN-9"}})[
            "sensors[0].serials"
        ]
    )
    # one port is one entry; a serial is declared once across entries
    twice = errors(
        ok,
        {"url": "/dev/ttyACM0", "serial": "SN-3"},
        {"url": "/dev/ttyACM2", "channels": {"4": "SN-2"}},
    )
    assert "sensors[0]" in twice["sensors[1].url"] and "'channels'" in twice["sensors[1].url"]
    assert "'SN-2' is already declared by sensors[0]" in twice["sensors[2].channels.4"]


@pytest.mark.parametrize("stability", ["fixed", "predictive"])
async def test_a_multiplexed_bridge_costs_no_more_chamber_time_than_a_bridge_each(
    sf, stability: str
) -> None:  # type: ignore[no-untyped-def]
    """Issue 12: the engine reads a position's sensors (and a soak's die probes) together,
    and on one multiplexing bridge that is one group capture: the three sensors of a
    position are read at one campaign time, and no reading is stored later than with a
    bridge per sensor. (Captured one after the other, the three 3.2 s captures of a
    position would put the last sensor's row 6.4 s after the first, every position.)

    "No later", not "at the same time": the twin with a bridge per sensor can only lose
    virtual time (a capture command written late by its port thread on a loaded machine
    lets the clock run on to the other bridges' wake-ups), never gain it."""
    spec = {**SPEC, "samples_per_position": 200, "stability": stability}  # 3.2 s at 62.5 Hz
    rows_t: dict[bool, dict[tuple[str | None, int, int], float]] = {}
    probes_t: dict[bool, list[tuple[str | None, float]]] = {}
    for multiplexed in (False, True):
        cid = _campaign(sf, spec)
        assert await _run_twin(sf, cid, {"multiplexed": multiplexed}) == "completed"
        camp, rows, _cals = _rows(sf, cid)
        assert not camp.sensors_dropped
        rows_t[multiplexed] = {(m.sensor, m.step, m.position): m.t_s for m in rows}
        with sf() as s:
            probes = s.scalars(select(SoakProbe).where(SoakProbe.campaign_id == cid)).all()
            probes_t[multiplexed] = [(p.sensor, p.t_s) for p in probes]
    assert rows_t[True].keys() == rows_t[False].keys() and len(rows_t[True]) == 3 * 6
    for key, t_s in rows_t[True].items():
        assert t_s <= rows_t[False][key] + 0.01, key
    for position in range(6):  # the three sensors of a position captured at once
        at = [rows_t[True][(s, 0, position)] for s in SERIALS]
        assert max(at) - min(at) < 0.01
    if stability == "predictive":  # every poll probes the three dies at once
        polls = Counter(round(t_s, 3) for _s, t_s in probes_t[True])
        assert len(polls) >= 2 and set(polls.values()) == {3}
