"""``rig check`` against the twin over Modbus TCP on loopback: shipped maps, a map file
written from the documentation alone, a wrong device and a dead link."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.protocols import Acquisition
from drivers.registermaps import CHAMBER_MAPS
from service.rig_check import Check, check_rig, format_report, passed
from simulators.chamber_sim import ChamberPhysics, ChamberRegisterImage, ControllerSetup
from simulators.faults import SimFaults
from simulators.modbus_server import start_modbus_server
from simulators.rig import start_sim_rig

# Written from "TestEquity F4T Controller, Chapter 3 Communications, Common Modbus Registers,
# F4T Mode (Data Map 1)", p. 15 (the cascade-control F4T), and the F4T user's guide p. 225 for
# the Hardware ID: nothing copied from the shipped files.
F4T_CASCADE = """
schema = "soakcal-register-map/1"
kind = "chamber"
name = "testequity-f4t-cascade"
undocumented = ["alarms: none in the table"]
[defaults]
word_order = "low_first"
[identity]
register = "hardware_id"
expect = 124
[run]
register = "event_1"
on = 63
off = 62
[[setup]]
register = "ramp_action"
value = 85
[registers.hardware_id]
address = 0
type = "int32"
source = "F4T guide p. 225"
[registers.setpoint_c]
address = 4042
type = "float32"
access = "rw"
source = "p. 15 Temperature Set Point"
[registers.working_setpoint_c]
address = 4190
type = "float32"
source = "p. 15 Closed Loop Set Point"
[registers.process_c]
address = 4182
type = "float32"
source = "p. 15 Actual Air Temperature (PV)"
[registers.ramp_action]
address = 4054
type = "uint16"
access = "rw"
source = "p. 15 Ramp Action, Set Point = 85"
[registers.ramp_c_per_min]
address = 4058
type = "uint16"
access = "rw"
source = "p. 15 Ramp Rate (manual ramp parameters are all 16-bit RW)"
[registers.event_1]
address = 16594
type = "uint16"
access = "rw"
source = "p. 15 Event 1, Off = 62, On = 63"
"""


def _config(sim: Any, chamber_map: str, chamber_url: str | None = None) -> dict[str, Any]:
    return {"name": "bench",
            "chamber": {"driver": "modbus", "url": chamber_url or sim.chamber_url,
                        "map": chamber_map},
            "turntable": {"url": sim.table_url, "map": sim.table_map},
            "sensors": [{"url": sim.sensor_url}]}


def _by(checks: list[Check], device: str, name: str) -> Check:
    return next(c for c in checks if c.device == device and c.check == name)


@pytest.mark.parametrize("chamber_map", sorted(CHAMBER_MAPS))
async def test_every_shipped_map_passes_against_the_twin(chamber_map: str) -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=chamber_map) as sim:
        checks = await check_rig(_config(sim, chamber_map), move=True, clock=clock)
        # The nudge and the move were put back.
        assert sim.chamber.setpoint_c == pytest.approx(23.0)
        assert sim.table.true_angles_deg() == pytest.approx((0.0, 0.0, 0.0))
    assert passed(checks), format_report(chamber_map, checks)
    assert _by(checks, "chamber", "setpoint_nudge").status == "pass"
    assert _by(checks, "turntable", "table_move").status == "pass"
    ident = _by(checks, "chamber", "identity")
    assert ident.status == ("skip" if CHAMBER_MAPS[chamber_map].identity is None else "pass")


async def test_without_move_nothing_is_written() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="watlow-f4t") as sim:
        checks = await check_rig(_config(sim, "watlow-f4t"), clock=clock)
        assert not sim.table.moving() and sim.chamber.setpoint_c == 23.0
    assert passed(checks)
    assert _by(checks, "turntable", "table_move").status == "skip"
    assert _by(checks, "chamber", "setpoint_nudge").status == "skip"


async def test_a_map_written_from_the_documentation_alone(tmp_path: Path) -> None:
    path = tmp_path / "testequity-f4t-cascade.toml"
    path.write_text(F4T_CASCADE)
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path)) as sim:
        checks = await check_rig(_config(sim, str(path)), move=True, clock=clock)
    assert passed(checks), format_report("doc-only", checks)
    assert "hardware_id = 124" in _by(checks, "chamber", "identity").detail


async def test_wrong_identity_fails_naming_both_values() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4) as sim:
        rng = np.random.default_rng(1)
        faults = SimFaults()
        # Another device at the chamber's address: an F4T layout whose Hardware ID reads 77.
        image = ChamberRegisterImage(ChamberPhysics(clock, rng), CHAMBER_MAPS["watlow-f4t"],
                                     identity_value=77)
        other = await start_modbus_server(image, faults, rng)
        try:
            checks = await check_rig(_config(sim, "watlow-f4t", other.url), clock=clock)
        finally:
            await other.stop()
    assert not passed(checks)
    bad = _by(checks, "chamber", "identity")
    assert bad.status == "fail" and "77" in bad.detail and "124" in bad.detail and bad.fix
    assert _by(checks, "sensor", "acquire").status == "pass"  # the rest is still checked


async def test_nobody_listening_fails_connect_with_a_fix() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4) as sim:
        checks = await check_rig(_config(sim, "eurotherm-3216", "tcp://127.0.0.1:9"),
                                 clock=clock)
    bad = _by(checks, "chamber", "connect")
    assert bad.status == "fail" and "device_id" in bad.fix
    assert _by(checks, "turntable", "status").status == "pass"


async def test_sensor_serial_named_in_the_rig_must_be_connected() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4) as sim:
        cfg = _config(sim, "eurotherm-3216")
        cfg["sensors"][0]["serial"] = "SN-K9"
        checks = await check_rig(cfg, clock=clock)
    bad = _by(checks, "sensor", "identity")
    assert bad.status == "fail" and "SN-K9" in bad.detail and "SN-0001" in bad.detail


async def test_a_map_check_register_set_wrongly_fails_naming_both_values() -> None:
    from drivers.modbus_link import ModbusLink

    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="watlow-f4t") as sim:
        link = ModbusLink(sim.chamber_url, clock)
        # The F4T left at its factory default display units, °F (30).
        await link.write_field(CHAMBER_MAPS["watlow-f4t"].registers["display_units"], 30)
        await link.close()
        checks = await check_rig(_config(sim, "watlow-f4t"), clock=clock)
    bad = _by(checks, "chamber", "register:display_units")
    assert bad.status == "fail" and "reads 30" in bad.detail and "expects 15" in bad.detail
    assert "C (15)" in bad.fix
    assert _by(checks, "chamber", "register:device_status").status == "pass"
    assert _by(checks, "chamber", "status").status == "pass"  # the rest still ran


async def test_a_table_moving_already_is_not_moved() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4) as sim:
        sim.table.move_to((90.0, 0.0, 0.0))  # someone else's move, 4.5 s long
        checks = await check_rig(_config(sim, "eurotherm-3216"), move=True, clock=clock)
    bad = _by(checks, "turntable", "table_move")
    assert bad.status == "fail" and "moving already" in bad.detail


async def test_sensor_part_ids_are_compared_when_the_bridge_reports_them() -> None:
    from dataclasses import dataclass

    from service.rig_check import _check_sensor, _Recorder

    @dataclass
    class Ident:
        model: str = "ADXL355"
        serial: str = "SN-1"
        firmware: str = "fw"
        devid_ad: int | None = 0xAD
        devid_mst: int | None = 0x1D
        partid: int | None = 0xED

    class Accel:
        def __init__(self, ident: Ident) -> None:
            self.ident = ident

        async def identify(self) -> Ident:
            return self.ident

        async def acquire(self, n: int) -> Acquisition:
            return Acquisition((0.0, 0.0, 1.0), (1e-4,) * 3, n, 23.0, 0.0, False, 0.1)

    rec = _Recorder()
    await _check_sensor(rec, Accel(Ident(partid=0xEC)), {"sensors": [{}]})
    bad = _by(rec.checks, "sensor", "identity")
    assert bad.status == "fail" and "0xEC" in bad.detail and "0xED" in bad.detail
    assert not any(c.check == "acquire" for c in rec.checks)  # a wrong part is not sampled
    rec = _Recorder()
    await _check_sensor(rec, Accel(Ident()), {"sensors": [{}]})
    good = _by(rec.checks, "sensor", "identity")
    assert good.status == "pass" and "part ids 0xAD 0x1D 0xED" in good.detail
    rec = _Recorder()
    await _check_sensor(rec, Accel(Ident(devid_ad=None, devid_mst=None, partid=None)),
                        {"sensors": [{}]})
    assert "reports no part ids" in _by(rec.checks, "sensor", "identity").detail
    assert passed(rec.checks)


async def test_every_channel_of_a_multiplexing_bridge_is_checked() -> None:
    clock = VirtualClock()
    serials = ["SN-C0", "SN-C1", "SN-C2"]
    async with start_sim_rig(clock, seed=4, serials=serials, multiplexed=True) as sim:
        sim.sensors[1].bridge.eeprom_serial = "SN-WRONG"  # another part on channel 1
        sim.sensors[2].bridge.part_ids = (0, 0, 0, 0)  # nothing answering on channel 2's CS
        cfg = _config(sim, "eurotherm-3216")
        cfg["sensors"][0]["channels"] = {str(i): s for i, s in enumerate(serials)}
        checks = await check_rig(cfg, clock=clock)
    assert not any(c.device == "sensor" for c in checks)  # no unaddressed check
    assert _by(checks, "sensor @0", "identity").status == "pass"
    assert _by(checks, "sensor @0", "acquire").status == "pass"
    bad = _by(checks, "sensor @1", "identity")
    assert bad.status == "fail" and "SN-WRONG" in bad.detail and "SN-C1" in bad.detail
    # a wrong part is not read further; the channels after it are still checked
    assert not any(c.device == "sensor @1" and c.check == "acquire" for c in checks)
    dead = _by(checks, "sensor @2", "identity")
    assert dead.status == "fail" and "0x00" in dead.detail


# --- physical plausibility: a twin set up unlike the map -------------------------------
#: The 3216 read through its 16-bit region, whose decimal point the instrument's display
#: setting implies: the layout a decimal-point misconfiguration mis-scales.
INT16_3216 = str(Path(__file__).with_name("data") / "eurotherm-3216-int16.toml")
# Each case: the controller's own setup, the map the lab wrote, and what rig check must
# say (the check that fails, words of its detail naming the cause, words of its fix).
MISCONFIGURED = {
    "whole degrees read as tenths (×10)": (
        ControllerSetup(decimals=0), INT16_3216, "pv_vs_die",
        ["PV reads 2.3 °C", "die reads 23.0 °C", "×10"],
        ["`scale = 10`→`1`", "`process_c`", "eurotherm-3216-int16.toml"]),
    "hundredths read as tenths (×0.1)": (
        ControllerSetup(decimals=2), INT16_3216, "pv_vs_die",
        ["PV reads 2", " °C while the die reads 23.0 °C", "×0.1"],
        ["`scale = 10`→`100`", "eurotherm-3216-int16.toml"]),
    "display in °F": (
        ControllerSetup(units="F"), "eurotherm-3216", "pv_vs_die",
        ["PV reads 73.4 °C", "°F"], ["units to °C", "`scale = 1.8`", "`offset = -17.7778`"]),
    "ramp units per hour": (
        ControllerSetup(ramp_per="hour"), "eurotherm-3216", "ramp",
        ["0.02 °C/min, commanded 1 °C/min: 60× slower", "per hour"],
        ["per minute", "`scale = 1`→`60`", "`ramp_c_per_min`", "eurotherm-3216.toml"]),
    "float words swapped": (
        ControllerSetup(swap_words=True), "watlow-f4t", "pv_vs_die",
        ["words", "swapped"], ["`word_order = \"high_first\"`", "watlow-f4t.toml"]),
    "alarm register missing on this model": (
        ControllerSetup(silent=frozenset({"alarms"})), "eurotherm-3216", "status",
        ["`alarms` (address 75) does not answer"], ["correct `address`", "eurotherm-3216.toml"]),
    "controller in manual": (
        ControllerSetup(mode="manual"), "eurotherm-3216", "mode",
        ["manual mode"], ["automatic"]),
}


@pytest.mark.parametrize("case", sorted(MISCONFIGURED))
async def test_a_map_unlike_the_controller_fails_naming_cause_and_key(case: str) -> None:
    setup, chamber_map, failing, detail_words, fix_words = MISCONFIGURED[case]
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=chamber_map, controller=setup) as sim:
        checks = await check_rig(_config(sim, chamber_map), move=True, clock=clock)
        # Whatever failed, nothing was left changed on the chamber.
        assert sim.chamber.setpoint_c == pytest.approx(23.0)
    assert not passed(checks)
    bad = _by(checks, "chamber", failing)
    assert bad.status == "fail", format_report(case, checks)
    for words in detail_words:
        assert words in bad.detail, bad.detail
    for words in fix_words:
        assert words in bad.fix, bad.fix


async def test_a_mis_scaled_chamber_is_not_nudged(monkeypatch: pytest.MonkeyPatch) -> None:
    """×10: a nudge of 0.5 °C through the map would write 5 °C; rig check writes nothing."""
    writes: list[int] = []
    image_write = ChamberRegisterImage.write

    def spy(self: ChamberRegisterImage, address: int, values: list[int]) -> Any:
        writes.append(address)
        return image_write(self, address, values)

    monkeypatch.setattr(ChamberRegisterImage, "write", spy)
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=INT16_3216,
                             controller=ControllerSetup(decimals=0)) as sim:
        checks = await check_rig(_config(sim, INT16_3216), move=True, clock=clock)
    assert writes == []
    assert "not nudged" in _by(checks, "chamber", "setpoint_nudge").detail


async def test_a_pv_register_pointing_elsewhere_names_the_address(tmp_path: Path) -> None:
    text = Path(INT16_3216).read_text()
    wrong = tmp_path / "lab-3216.toml"
    # A slip of the pen: PV at 4 (nothing there on this controller) instead of 1.
    wrong.write_text(text.replace("[registers.process_c]\naddress = 1\n",
                                  "[registers.process_c]\naddress = 4\n"))
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=INT16_3216) as sim:
        checks = await check_rig(_config(sim, str(wrong)), move=True, clock=clock)
    bad = _by(checks, "chamber", "pv_vs_die")
    assert bad.status == "fail" and "PV reads 0.0 °C" in bad.detail
    assert "reads all bits 0, as an address with nothing behind it does" in bad.detail
    assert "`address` of register `process_c` in lab-3216.toml" in bad.fix


async def test_a_pv_that_no_misreading_explains_is_not_given_a_cause() -> None:
    """The sensor is in another chamber (its die 40 °C warmer): no cause is guessed."""
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="eurotherm-3216") as sim:
        sim.chamber.die_c = 63.0
        sim.chamber.die_tau_s = 1e9  # the die stays where it is
        checks = await check_rig(_config(sim, "eurotherm-3216"), move=True, clock=clock)
    bad = _by(checks, "chamber", "pv_vs_die")
    assert bad.status == "fail"
    assert "no scale, unit or word-order error explains it" in bad.detail
    assert "the sensor is inside this chamber" in bad.fix


@pytest.mark.parametrize("chamber_map", ["eurotherm-3216", "eurotherm-2400"])
async def test_the_eurotherm_maps_read_floats_whatever_the_decimal_point(
        chamber_map: str) -> None:
    """The IEEE region carries full resolution: a Eurotherm set to whole degrees reads right."""
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=chamber_map,
                             controller=ControllerSetup(decimals=0)) as sim:
        checks = await check_rig(_config(sim, chamber_map), move=True, clock=clock)
    assert passed(checks), format_report(f"{chamber_map} whole degrees", checks)
    assert _by(checks, "chamber", "pv_vs_die").status == "pass"
    if chamber_map == "eurotherm-3216":
        assert _by(checks, "chamber", "register:ramp_units").status == "pass"


async def test_a_well_set_up_controller_passes_the_ramp_and_die_checks() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="eurotherm-3216") as sim:
        checks = await check_rig(_config(sim, "eurotherm-3216"), move=True, clock=clock)
    ramp = _by(checks, "chamber", "ramp")
    assert ramp.status == "pass" and "commanded 1 °C/min" in ramp.detail
    assert _by(checks, "chamber", "pv_vs_die").status == "pass"


async def test_a_stopped_chamber_is_not_started_to_watch_its_ramp() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="soakcal-twin-chamber") as sim:
        checks = await check_rig(_config(sim, "soakcal-twin-chamber"), move=True, clock=clock)
        assert not sim.chamber.running
    assert _by(checks, "chamber", "ramp").status == "skip"


async def test_an_identity_mismatch_prints_the_register_as_an_integer() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4) as sim:
        rng = np.random.default_rng(1)
        image = ChamberRegisterImage(ChamberPhysics(clock, rng), CHAMBER_MAPS["watlow-f4t"],
                                     identity_value=8126464)
        other = await start_modbus_server(image, SimFaults(), rng)
        try:
            checks = await check_rig(_config(sim, "watlow-f4t", other.url), clock=clock)
        finally:
            await other.stop()
    bad = _by(checks, "chamber", "identity")
    assert bad.detail == "register hardware_id reads 8126464, map watlow-f4t expects 124"


# Map format v2: input registers, a coil, a discrete input and single-register writes,
# with the same addresses in different tables (separate address spaces in Modbus).
TABLES_MAP = """
schema = "soakcal-register-map/1"
kind = "chamber"
name = "tables-chamber"
[run]
register = "run"
[[checks]]
register = "door_closed"
expect = 1
what = "the chamber door is closed"
[registers.process_c]
table = "input"
address = 0
type = "int16"
scale = 10
[registers.working_setpoint_c]
table = "input"
address = 1
type = "int16"
scale = 10
[registers.setpoint_c]
address = 0
type = "int16"
scale = 10
access = "rw"
write = "single"
[registers.ramp_c_per_min]
address = 1
type = "uint16"
scale = 10
access = "rw"
write = "single"
[registers.run]
table = "coil"
address = 0
type = "bit"
access = "rw"
[registers.door_closed]
table = "discrete"
address = 0
type = "bit"
"""


async def test_a_map_with_input_registers_coils_and_single_writes(tmp_path: Path) -> None:
    path = tmp_path / "tables.toml"
    path.write_text(TABLES_MAP)
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path)) as sim:
        sim.chamber.running = True  # as if started: the ramp is watched while it runs
        checks = await check_rig(_config(sim, str(path)), move=True, clock=clock)
    assert passed(checks), format_report("tables", checks)
    assert _by(checks, "chamber", "register:door_closed").detail == "the chamber door is closed"
    assert _by(checks, "chamber", "ramp").status == "pass"
    assert "running" in _by(checks, "chamber", "status").detail  # read from the coil


async def test_the_maps_unit_id_applies_unless_the_rig_gives_device_id(tmp_path: Path) -> None:
    from service.engine.rigs import open_rig

    path = tmp_path / "unit17.toml"
    path.write_text(Path(INT16_3216).read_text().replace(
        'word_order = "high_first"', 'word_order = "high_first"\nunit_id = 17'))
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path)) as sim:
        cfg = _config(sim, str(path))
        async with open_rig(cfg, clock) as devices:
            assert devices.chamber.link.device_id == 17
        cfg["chamber"]["device_id"] = 3
        async with open_rig(cfg, clock) as devices:
            assert devices.chamber.link.device_id == 3


def test_soakcal_sim_refuses_a_silent_register_the_map_lacks(
        capsys: pytest.CaptureFixture[str]) -> None:
    from simulators.cli import run_sim

    assert run_sim(["--silent", "alarmz", "--duration-s", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("soakcal sim: --silent alarmz: map eurotherm3216 names no such register")
    assert run_sim(["--hold", "ramp_units=hour", "--duration-s", "0"]) == 2
    assert capsys.readouterr().err.strip() == (
        "soakcal sim: --hold ramp_units=hour: expected REGISTER=NUMBER")
    assert run_sim(["--hold", "loop_mode=54", "--duration-s", "0"]) == 2
    assert "names no register 'loop_mode'" in capsys.readouterr().err


async def test_soakcal_sim_serves_the_controller_set_up_as_asked(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """--decimals 0 --units F: read with the tenths-of-°C map, 23 °C shows as 7.3."""
    import asyncio

    import simulators.cli as sim_cli
    from drivers.clock import RealClock
    from drivers.modbus_link import ModbusLink
    from drivers.registermaps import load_chamber_map

    started: asyncio.Queue[Any] = asyncio.Queue()
    monkeypatch.setattr(sim_cli, "describe", lambda rig: started.put_nowait(rig) or "")
    args = sim_cli.build_parser().parse_args(
        ["--decimals", "0", "--units", "F", "--duration-s", "2", "--chamber-map", INT16_3216])
    args.truth, args.die_tau_s = None, 900.0
    serving = asyncio.create_task(sim_cli._serve(args))
    rig = await asyncio.wait_for(started.get(), 5)
    link = ModbusLink(rig.chamber_url, RealClock())
    try:
        pv = await link.read_field(load_chamber_map(INT16_3216).process_c)
    finally:
        await link.close()
        serving.cancel()
    assert pv == pytest.approx(7.3, abs=0.11)  # 73 °F in whole degrees, read as tenths


async def test_an_enumerated_alarm_state_is_reported_by_its_name(tmp_path: Path) -> None:
    from drivers.modbus_link import ModbusLink
    from drivers.registermaps import load_chamber_map

    path = tmp_path / "states.toml"
    text = Path(INT16_3216).read_text() + """
[registers.alarm_1_state]
address = 1600
type = "uint16"
access = "rw"
states = { 61 = "none", 88 = "startup", 7 = "alarm high", 8 = "alarm low", 28 = "error" }
ok = [61, 88]
"""
    # a top-level key goes before the first table
    path.write_text(text.replace('schema = "soakcal-register-map/1"\n',
                                 'schema = "soakcal-register-map/1"\n'
                                 'alarm_states = ["alarm_1_state"]\n', 1))
    regmap = load_chamber_map(path)
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path)) as sim:
        ok_checks = await check_rig(_config(sim, str(path)), clock=clock)
        link = ModbusLink(sim.chamber_url, clock)
        await link.write_field(regmap.registers["alarm_1_state"], 7)
        await link.close()
        checks = await check_rig(_config(sim, str(path)), clock=clock)
    assert _by(ok_checks, "chamber", "alarms").status == "pass"  # the twin starts in "none"
    bad = _by(checks, "chamber", "alarms")
    assert bad.status == "fail" and bad.detail == "active: alarm_1_state: alarm high"


@pytest.mark.parametrize(("mean_g", "words"), [
    ((0.0, 0.0, 0.5), "×0.5: the range setting and the scale the driver assumes disagree"),
    ((0.0, 0.0, 9.80665), "it reads in m/s², not g"),
    ((0.0, 0.3, 0.5), "outside 0.9…1.1 g of local gravity"),
])
async def test_a_sensor_off_gravity_names_the_misreading(mean_g: tuple[float, float, float],
                                                         words: str) -> None:
    from service.rig_check import _check_sensor, _Recorder

    class Accel:
        async def identify(self) -> Any:
            from types import SimpleNamespace
            return SimpleNamespace(model="ADXL355", serial="SN-1", firmware="fw")

        async def acquire(self, n: int) -> Acquisition:
            return Acquisition(mean_g, (1e-4,) * 3, n, 23.0, 0.0, False, 0.1)

    rec = _Recorder()
    await _check_sensor(rec, Accel(), {"sensors": [{}]})
    bad = _by(rec.checks, "sensor", "acquire")
    assert bad.status == "fail" and words in bad.detail


async def test_swapped_words_near_0_c_are_not_taken_for_a_reading() -> None:
    """Swapped float words often decode to ~1e-38: near 0 °C that must not 'agree'."""
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="watlow-f4t", start_c=3.0,
                             controller=ControllerSetup(swap_words=True)) as sim:
        checks = await check_rig(_config(sim, "watlow-f4t"), move=True, clock=clock)
    bad = _by(checks, "chamber", "pv_vs_die")
    assert bad.status == "fail" and "words of the 32-bit value are swapped" in bad.detail


# (map, register the controller holds, value held, the check's detail — whole, or its start
# when it ends in "…" —, a phrase of the fix)
MODE_CHECKS = [
    ("watlow-f4t", "loop_mode", 54.0,
     "loop_mode reads 54, map watlow-f4t expects one of 10, 62 "
     "(loop 1 is not in manual (Auto 10 or Off 62))", "switch loop 1 to Auto"),
    ("eurotherm-2400", "mode", 1.0,
     "mode reads 1, map eurotherm-2400 expects 0 (the loop is in Auto (Auto-man select = 0))",
     "switch the 2400 to Auto"),
    ("watlow-f4t-cascade", "simple_setpoint", 62.0,
     "simple_setpoint reads 62, map watlow-f4t-cascade expects 63…",
     "set Simple Set Point to On (63, register 4200)"),
]


@pytest.mark.parametrize(("chamber_map", "register", "held", "detail", "fix"), MODE_CHECKS,
                         ids=[row[0] for row in MODE_CHECKS])
async def test_a_controller_left_in_the_wrong_mode_fails_its_check(
        chamber_map: str, register: str, held: float, detail: str, fix: str) -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=chamber_map,
                             controller=ControllerSetup(holds=((register, held),))) as sim:
        checks = await check_rig(_config(sim, chamber_map), clock=clock)
    bad = _by(checks, "chamber", f"register:{register}")
    assert bad.status == "fail"
    if detail.endswith("…"):
        assert bad.detail.startswith(detail[:-1])
    else:
        assert bad.detail == detail
    assert fix in bad.fix


def test_a_ramp_ratio_no_map_mistake_explains_is_not_blamed_on_the_map() -> None:
    """A twin run 60× against a rig config of 4× shows the WSP ramping 15× too fast: no
    scale or unit gives 15, so the fix names the rig's time_scale, not a new scale."""
    from service.rig_plausibility import _ramp_cause

    cause, fix = _ramp_cause(15.0, 1.0, "watlow-f4t.toml")
    assert "no scale or unit mistake" in cause
    assert "`time_scale`" in fix and "`scale =" not in fix
    cause, fix = _ramp_cause(10.3, 1.0, "watlow-f4t.toml")
    assert "off by ×10" in cause and "`scale = 1`→`0.1`" in fix


# --- turntables: commanded vs read-back angles, homing, a hand-axis stage ---------------

LEADSHINE_TEXT = (Path(__file__).parents[2] / "drivers" / "maps"
                  / "leadshine-rs485-pr.toml").read_text()
# A homing start for the twin only: the value is not in the drive manual's pages read.
TEST_HOME = """
[[sequence.home]]
register = "pr_control"
value = 32
[registers.pr_control]
address = 24578
type = "uint16"
access = "w"
"""


def _drive_map(tmp_path: Path, *, readback: bool = True, home: bool = False) -> str:
    text = LEADSHINE_TEXT
    if not readback:
        text = text.replace("[registers.position_deg]", "[registers.feedback]").replace(
            'kind = "turntable"', 'kind = "turntable"\nabsent_roles = ["position_deg"]')
    path = tmp_path / "drive.toml"
    path.write_text(text + (TEST_HOME if home else ""))
    return str(path)


async def test_a_table_without_readback_says_its_angles_are_commanded(tmp_path: Path) -> None:
    table_map = _drive_map(tmp_path, readback=False)
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, table_map=table_map) as sim:
        checks = await check_rig(_config(sim, sim.chamber_map), move=True, clock=clock)
    assert passed(checks), format_report("bench", checks)
    status, move = _by(checks, "turntable", "status"), _by(checks, "turntable", "table_move")
    assert status.detail.startswith("angles (0.00, 0.00)° (commanded, not read back: map "
                                    "leadshine-rs485-pr has no position readback)")
    assert move.detail.endswith("(commanded angles: map leadshine-rs485-pr has no position "
                                "readback, so only the drive's in-position report is "
                                "checked, not where the axis stopped)")


async def test_a_table_with_readback_and_homed_says_so() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, table_map="leadshine-rs485-pr") as sim:
        checks = await check_rig(_config(sim, sim.chamber_map), clock=clock)
    assert passed(checks), format_report("bench", checks)
    assert "(read back)" in _by(checks, "turntable", "status").detail
    assert _by(checks, "turntable", "homed").detail == "every axis reports homed"
    # soakcal's own table layout has no homed bit: no homing check at all.
    async with start_sim_rig(clock, seed=4) as sim:
        checks = await check_rig(_config(sim, sim.chamber_map), clock=clock)
    assert not [c for c in checks if c.check == "homed"]


async def test_a_table_not_homed_fails_saying_how_to_home_it(tmp_path: Path) -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, table_map=_drive_map(tmp_path, home=True)) as sim:
        checks = await check_rig(_config(sim, sim.chamber_map), clock=clock)
    assert not passed(checks)
    homed = _by(checks, "turntable", "homed")
    assert homed.status == "fail"
    assert homed.detail.startswith("not homed: the angles count from where the table stood")
    assert homed.fix.startswith("home every axis before a campaign: the map's "
                                "[[sequence.home]] starts it")


async def test_a_hand_axis_stage_says_the_hand_angle_is_not_read(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", f"sqlite:///{tmp_path / 'db.sqlite'}")
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, table_map="leadshine-rs485-pr") as sim:
        rig = _config(sim, sim.chamber_map)
        rig["turntable"].update(axes=1, hand_axis={"steps_deg": [0, 90, 180, 270]})
        checks = await check_rig(rig, clock=clock)
    assert passed(checks), format_report("bench", checks)
    # The motor's drive is identified through its map (the stage itself has none).
    assert _by(checks, "turntable", "identity").status == "skip"
    assert _by(checks, "turntable", "status").detail.startswith(
        "motor (0.00)° (read back), hand axis 0.00° (set by hand, not read; asked only in a "
        "campaign)")
