"""Map files: shipped ones load and cite sources; bad files are refused naming file and key."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from drivers import registermaps
from drivers.registermaps import (
    CHAMBER_MAPS,
    Field,
    MapError,
    load_chamber_map,
    load_map,
    load_turntable_map,
    shipped_maps,
)

GOOD = """
schema = "soakcal-register-map/1"
kind = "chamber"
name = "test-chamber"
[registers.process_c]
address = 1
type = "int16"
scale = 10
[registers.setpoint_c]
address = 2
type = "int16"
scale = 10
access = "rw"
[registers.working_setpoint_c]
address = 5
type = "int16"
scale = 10
[registers.ramp_c_per_min]
address = 35
type = "uint16"
scale = 10
access = "rw"
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "lab.toml"
    path.write_text(text)
    return path


def test_every_shipped_map_loads_and_names_itself() -> None:
    for name, path in shipped_maps().items():
        assert load_map(path).name == name


MANUFACTURER_MAPS = sorted(n for n in shipped_maps() if not n.startswith("soakcal-"))


def test_the_manufacturer_maps_are_the_ones_shipped() -> None:
    assert {"eurotherm-2400", "eurotherm-3216", "watlow-f4t",
            "watlow-f4t-cascade"} <= set(MANUFACTURER_MAPS)


@pytest.mark.parametrize("name", MANUFACTURER_MAPS)
def test_manufacturer_maps_cite_a_document_for_every_register(name: str) -> None:
    doc = tomllib.loads(shipped_maps()[name].read_text())
    assert doc["source"]["document"] and doc["source"]["table"]
    for reg, spec in doc["registers"].items():
        assert spec.get("source"), f"{name}: registers.{reg} has no citation"
    assert doc["undocumented"], "what the documents do not say must be listed"


def test_eurotherm_addresses_are_the_handbooks() -> None:
    m = CHAMBER_MAPS["eurotherm-3216"]
    # Parameters 1, 2, 5, 35 of the handbook's table, in the IEEE region 0x8000 + 2·n.
    assert (m.process_c.address, m.setpoint_c.address, m.working_setpoint_c.address,
            m.ramp_c_per_min.address) == tuple(0x8000 + 2 * n for n in (1, 2, 5, 35))
    assert {m.process_c.encoding, m.ramp_c_per_min.encoding} == {"float32"}
    assert [(c.register, c.expect) for c in m.checks] == [("ramp_units", 0.0)]
    assert m.alarms is not None and m.alarms.address == 75
    assert m.alarm_bits[5] == "sensor_break" and m.info_bits[4] == "manual_mode"
    assert m.run is None and m.identity is None  # not in the cited table: not invented


def test_eurotherm_2400_addresses_are_the_communications_handbooks() -> None:
    m = CHAMBER_MAPS["eurotherm-2400"]
    # HA026230 p. 5-4: PV 1, target SP 2, working SP 5; SP rate 35 (undocumented there);
    # all in the 2000-series IEEE region 8000h + 2n (HA027664 B.8.1), high word first (7.4).
    assert (m.process_c.address, m.setpoint_c.address, m.working_setpoint_c.address,
            m.ramp_c_per_min.address) == tuple(0x8000 + 2 * n for n in (1, 2, 5, 35))
    assert m.setpoint_c.address == 0x8004  # the handbook's own worked example
    assert {m.process_c.word_order, m.setpoint_c.word_order} == {"high_first"}
    assert [(c.register, c.expect) for c in m.checks] == [("mode", 0.0)]
    assert m.alarms is not None and m.alarms.address == 76
    assert m.alarm_bits == {1: "pv_sensor_broken", 2: "pv_out_of_sensor_range",
                            6: "loop_break"}
    assert m.info_bits[15] == "manual_mode"
    assert m.run is None and m.identity is None  # not verified: not invented
    doc = tomllib.loads(shipped_maps()["eurotherm-2400"].read_text())
    assert any(u.startswith("setpoint rate limit: parameter 35") for u in doc["undocumented"])


def test_f4t_cascade_reads_the_air_loop_of_the_cascade_table() -> None:
    m = CHAMBER_MAPS["watlow-f4t-cascade"]
    # TestEquity F4T (cascade) ch. 3 p. 15: SP 4042, closed-loop SP 4190, air PV 4182 (the
    # part PV is 4180), manual ramp action 4054 / scale 2956 / rate 4058, all low word first.
    assert (m.setpoint_c.address, m.working_setpoint_c.address, m.process_c.address,
            m.ramp_c_per_min.address) == (4042, 4190, 4182, 4058)
    assert m.process_c.word_order == "low_first" and m.ramp_c_per_min.encoding == "uint16"
    assert [(f.address, v) for f, v in m.setup] == [(4054, 85.0), (2956, 57.0)]
    assert [c.register for c in m.checks] == ["device_status", "display_units",
                                              "simple_setpoint"]
    assert m.checks[2].expect == 63.0  # Simple Set Point On: cascade control off
    assert m.identity is not None and m.identity.expect == 124.0
    assert m.alarm_states == () and m.alarms is None  # none in the cited table


def test_f4t_identity_run_and_ramp_setup() -> None:
    m = CHAMBER_MAPS["watlow-f4t"]
    assert m.identity is not None and m.identity.expect == 124.0
    assert m.identity.field.encoding == "int32"
    assert m.run is not None and (m.run_on, m.run_off) == (63, 62)
    assert [(f.address, v) for f, v in m.setup] == [(2794, 85.0), (2796, 57.0)]
    assert m.process_c.word_order == "low_first"
    # The control loop's PV, not Universal Input 1 (27586); alarms as enumerated states.
    assert m.process_c.address == 2820
    assert [(a.register, a.field.address, sorted(a.ok)) for a in m.alarm_states] == [
        ("alarm_1_state", 1356, [12, 61, 88]), ("alarm_2_state", 1456, [12, 61, 88])]


def test_old_names_and_paths_resolve(tmp_path: Path) -> None:
    assert load_chamber_map("eurotherm3216").name == "eurotherm-3216"
    assert load_chamber_map("watlow_f4t").name == "watlow-f4t"
    assert load_turntable_map("soakcal_table").name == "soakcal-table"
    assert load_chamber_map(str(_write(tmp_path, GOOD))).name == "test-chamber"
    with pytest.raises(MapError, match="not a shipped map"):
        load_chamber_map("eurotherm-9999")
    with pytest.raises(MapError, match="describes a chamber"):
        load_turntable_map("eurotherm-3216")


def test_duplicated_register_key_is_refused_with_file_line_and_column(tmp_path: Path) -> None:
    text = GOOD + "[registers.process_c]\naddress = 9\ntype = \"int16\"\n"
    path = _write(tmp_path, text)
    with pytest.raises(MapError) as err:
        load_map(path)
    assert str(path) in str(err.value) and "line" in str(err.value)


def test_two_names_on_one_register_are_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, GOOD + "[registers.alarms]\naddress = 5\ntype = \"uint16\"\n")
    with pytest.raises(MapError) as err:
        load_map(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and "registers.alarms.address" in msg
    assert "working_setpoint_c" in msg


def test_unknown_type_is_refused_with_the_key(tmp_path: Path) -> None:
    path = _write(tmp_path, GOOD.replace('type = "uint16"', 'type = "uint24"'))
    with pytest.raises(MapError) as err:
        load_map(path)
    assert str(path) in str(err.value)
    assert "registers.ramp_c_per_min.type" in str(err.value) and "uint24" in str(err.value)


def test_missing_required_register_is_refused(tmp_path: Path) -> None:
    text = GOOD.replace("[registers.working_setpoint_c]\naddress = 5",
                        "[registers.wsp]\naddress = 5")
    path = _write(tmp_path, text)
    with pytest.raises(MapError) as err:
        load_map(path)
    assert f"{path}: registers.working_setpoint_c: missing" in str(err.value)


def test_reference_to_an_unknown_register_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, GOOD + "[run]\nregister = \"power\"\non = 1\noff = 0\n")
    with pytest.raises(MapError, match=r"run\.register: names no register"):
        load_map(path)


def test_int32_both_word_orders_round_trip() -> None:
    for order in ("high_first", "low_first"):
        f = Field(0, "int32", 1.0, order)  # type: ignore[arg-type]
        for value in (124.0, -2.0, 2.0**31 - 1):
            assert f.decode(f.encode(value)) == value
    assert Field(0, "int32", 1.0, "low_first").encode(124.0) == [124, 0]
    with pytest.raises(ValueError):
        Field(0, "int32").encode(2.0**31)


def test_sim_refuses_a_bad_map_file_with_exit_2(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    from simulators.cli import run_sim

    path = _write(tmp_path, GOOD.replace('type = "uint16"', 'type = "word"'))
    assert run_sim(["--chamber-map", str(path), "--duration-s", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "registers.ramp_c_per_min.type" in err


def test_a_misspelt_key_is_refused_not_ignored(tmp_path: Path) -> None:
    path = _write(tmp_path, GOOD.replace("scale = 10\naccess = \"rw\"",
                                         "scale = 10\nacess = \"rw\"", 1))
    with pytest.raises(MapError, match=r"registers\.setpoint_c\.acess: unknown key"):
        load_map(path)
    path = _write(tmp_path, GOOD + "[limit]\nrange_c = [-40, 85]\n")
    with pytest.raises(MapError, match=r": limit: unknown key"):
        load_map(path)
    path = _write(tmp_path, GOOD + "[limits]\nrange = [-40, 85]\n")
    with pytest.raises(MapError, match=r"limits\.range: unknown key"):
        load_map(path)


def test_the_documented_example_map_loads(tmp_path: Path) -> None:
    doc = (Path(__file__).parents[2] / "docs" / "registers.md").read_text()
    example = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    m = load_chamber_map(str(_write(tmp_path, example)))
    assert m.name == "our-chamber" and m.identity is not None and m.run is not None
    assert m.max_ramp_c_per_min == 3.0 and m.process_c.word_order == "low_first"


def test_map_checks_load_and_refer_to_registers(tmp_path: Path) -> None:
    checks = {c.register: c.wanted() for c in CHAMBER_MAPS["watlow-f4t"].checks}
    assert checks == {"device_status": "138", "loop_mode": "one of 10, 62",
                      "display_units": "15"}
    path = _write(tmp_path, GOOD + "[[checks]]\nregister = \"units\"\nexpect = 15\n")
    with pytest.raises(MapError, match=r"checks\[0\]\.register: names no register"):
        load_map(path)


def test_a_register_the_driver_writes_must_be_writable(tmp_path: Path) -> None:
    path = _write(tmp_path, GOOD.replace('scale = 10\naccess = "rw"\n[registers.working',
                                         'scale = 10\naccess = "r"\n[registers.working', 1))
    with pytest.raises(MapError, match=r"registers\.setpoint_c\.access: the driver writes"):
        load_map(path)
    path = _write(tmp_path, GOOD + "[registers.alarms]\naddress = 74\ntype = \"float32\"\n")
    with pytest.raises(MapError, match=r"registers\.alarms\.type: a bit word"):
        load_map(path)


TABLE = """
schema = "soakcal-register-map/1"
kind = "turntable"
name = "test-table"
[axes]
count = 2
stride = 2
[registers.position_deg]
address = 100
type = "float32"
[registers.status]
address = 106
type = "uint16"
bits = { 0 = "in_position", 1 = "moving" }
[registers.target_deg]
address = 200
type = "float32"
access = "rw"
[registers.command]
address = 210
type = "uint16"
access = "w"
"""

# (map text, the key the refusal must name, words of its reason)
REFUSED = {
    "4xxxx reference": (GOOD.replace("address = 35\n", "address = 40036\n"),
                        "registers.ramp_c_per_min.address",
                        "40036 looks like a 4xxxx holding-register reference"),
    "negative max ramp": (GOOD + "[limits]\nmax_ramp_c_per_min = -2.0\n",
                          "limits.max_ramp_c_per_min", "> 0 °C/min, got -2"),
    "absurd block gap": (GOOD + "[limits]\nblock_read_max_gap = 100000\n",
                         "limits.block_read_max_gap", "one read returns at most 125"),
    "int32 at the last register": (
        GOOD + "[registers.hours]\naddress = 65535\ntype = \"int32\"\n",
        "registers.hours.address", "past the last one (65535)"),
    "bad default word order": (
        GOOD + "[defaults]\nword_order = \"middle\"\n", "defaults.word_order",
        "got 'middle'"),
    "axis past the last register": (
        TABLE.replace("address = 200\n", "address = 65533\n"), "registers.target_deg.address",
        "axis 1 lands at 65535"),
    "negative table range": (TABLE + "[limits]\nrange_deg = -1\n", "limits.range_deg",
                             "> 0°, got -1"),
    "input register written": (
        GOOD.replace('address = 2\ntype = "int16"', 'address = 2\ntable = "input"\ntype = "int16"'),
        "registers.setpoint_c.access", "input registers are read-only in Modbus"),
    "coil that is not a bit": (
        GOOD + "[registers.door]\ntable = \"coil\"\naddress = 0\ntype = \"uint16\"\n",
        "registers.door.type", "a coil register is type \"bit\""),
    "single write of a float": (
        GOOD + "[registers.sp2]\naddress = 50\ntype = \"float32\"\naccess = \"rw\"\n"
        "write = \"single\"\n", "registers.sp2.write", "carries one holding register"),
    "safe angle outside the range": (
        TABLE + "[limits]\nrange_deg = 180\n[safe]\nangles_deg = [0.0, 270.0]\n",
        "safe.angles_deg[1]", "270.0° outside limits.range_deg ±180°"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_map_wrong_in_substance_is_refused_naming_key(tmp_path: Path, case: str) -> None:
    text, key, why = REFUSED[case]
    path = _write(tmp_path, text)
    with pytest.raises(MapError) as exc:
        load_map(path)
    assert str(exc.value).startswith(f"{path}: {key}: "), str(exc.value)
    assert why in str(exc.value)


def test_a_non_utf8_map_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "lab.toml"
    path.write_bytes(GOOD.replace("test-chamber", "régulateur").encode("latin-1"))
    with pytest.raises(MapError, match=r"not UTF-8 text \(byte 0xE9 at offset \d+\): save"):
        load_map(path)


def test_a_4xxxx_address_the_manual_really_gives_can_be_said_so(tmp_path: Path) -> None:
    text = GOOD.replace("address = 35\n", "address = 40036\nprotocol_address = true\n")
    assert load_chamber_map(_write(tmp_path, text)).ramp_c_per_min.address == 40036


def test_offset_and_scale_map_a_fahrenheit_register() -> None:
    # 0.1 °F per count: 73.4 °F (734 counts) is 23.0 °C.
    f = Field(1, "int16", scale=18.0, offset=-160 / 9)
    assert f.decode([734]) == pytest.approx(23.0)
    assert f.encode(23.0) == [734]


def test_rig_validate_says_ok_or_names_file_and_key(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from service.cli import main

    assert main(["rig", "validate", "eurotherm-3216"]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith("OK: eurotherm-3216 — Eurotherm 3216") and "chamber" in out
    assert main(["rig", "validate", str(_write(tmp_path, TABLE))]) == 0
    assert "turntable, 2 axes" in capsys.readouterr().out
    bad = _write(tmp_path, REFUSED["bad default word order"][0])
    assert main(["rig", "validate", str(bad)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.strip() == (f"soakcal rig validate: {bad}: defaults.word_order: "
                                    "expected \"high_first\" or \"low_first\", got 'middle'")


def test_checks_accept_a_value_a_set_or_a_range(tmp_path: Path) -> None:
    text = GOOD + """[registers.units]
address = 90
type = "uint16"
[registers.status]
address = 91
type = "uint16"
[registers.band]
address = 92
type = "int16"
[[checks]]
register = "units"
expect = 15
[[checks]]
register = "status"
one_of = [138, 139]
[[checks]]
register = "band"
min = -5
max = 5
"""
    exact, in_set, in_range = load_chamber_map(_write(tmp_path, text)).checks
    assert exact.accepts(15) and not exact.accepts(30) and exact.wanted() == "15"
    assert in_set.accepts(139) and not in_set.accepts(32)
    assert in_set.wanted() == "one of 138, 139" and in_set.expect == 138
    assert in_range.accepts(-5) and in_range.accepts(5) and not in_range.accepts(5.5)
    assert in_range.wanted() == "-5…5"
    both = text.replace("one_of = [138, 139]", "one_of = [138]\nexpect = 138")
    with pytest.raises(MapError, match=r"checks\[1\]: expected exactly one of expect, one_of, "
                                       r"min/max, got expect, one_of"):
        load_map(_write(tmp_path, both))
    with pytest.raises(MapError, match=r"checks\[2\]\.min: min 5 > max -5"):
        load_map(_write(tmp_path, text.replace("min = -5\nmax = 5", "min = 5\nmax = -5")))


def test_a_map_may_name_its_device_unit_id(tmp_path: Path) -> None:
    m = load_chamber_map(_write(tmp_path, GOOD + "[defaults]\nunit_id = 17\n"))
    assert m.unit_id == 17 and CHAMBER_MAPS["eurotherm-3216"].unit_id == 1
    with pytest.raises(MapError, match=r"defaults\.unit_id: expected a Modbus unit id 0…247"):
        load_map(_write(tmp_path, GOOD + "[defaults]\nunit_id = 300\n"))


def test_state_registers_must_name_their_ok_states(tmp_path: Path) -> None:
    base = 'alarm_states = ["al1"]\n' + GOOD + "[registers.al1]\naddress = 90\ntype = \"uint16\"\n"
    states = 'states = { 61 = "none", 7 = "high" }\nok = [61]\n'
    m = load_chamber_map(_write(tmp_path, base + states))
    (al1,) = m.alarm_states
    assert al1.alarm(61) is None and al1.alarm(7) == "al1: high" and al1.alarm(9) == "al1: state 9"
    with pytest.raises(MapError, match=r"registers\.al1\.ok: expected the list of non-alarm"):
        load_map(_write(tmp_path, base + 'states = { 61 = "none" }\nok = [62]\n'))
    stray = GOOD + "[registers.al1]\naddress = 90\ntype = \"uint16\"\nstates = { 61 = \"none\" }\n"
    with pytest.raises(MapError, match=r"registers\.al1\.states: only registers listed in "):
        load_map(_write(tmp_path, stray))


def test_safe_stop_must_be_a_boolean_and_needs_a_run_register(tmp_path: Path) -> None:
    text = (Path(registermaps.__file__).parent / "maps" / "soakcal-twin-chamber.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[safe]\nsetpoint_c = 23.0", "[safe]\nsetpoint_c = 23.0\nstop = 1"))
    with pytest.raises(registermaps.MapError, match="safe.stop"):
        registermaps.load_chamber_map(bad)
    no_run = (Path(registermaps.__file__).parent / "maps" / "eurotherm-3216.toml").read_text()
    assert "[run]" not in no_run
    bad.write_text(no_run.replace("[safe]\nsetpoint_c = 23.0",
                                  "[safe]\nsetpoint_c = 23.0\nstop = true"))
    with pytest.raises(registermaps.MapError, match="needs a \\[run\\] register"):
        registermaps.load_chamber_map(bad)
