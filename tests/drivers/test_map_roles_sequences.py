"""Optional roles (``absent_roles``) and write sequences (``[[sequence.NAME]]``), from the
map file through the driver to the twin over Modbus TCP: a controller without a
working setpoint or a static ramp (CSZ EZT-430i), and one whose setpoint change needs a
profile terminated first (Watlow F4)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from drivers.clock import VirtualClock
from drivers.faults import ValueOutOfRange
from drivers.registermaps import CHAMBER_MAPS, MapError, load_map
from service.engine.rigs import open_rig
from service.rig_check import Check, check_rig, format_report, passed
from simulators.chamber_sim import ControllerSetup
from simulators.rig import start_sim_rig

MAPS = Path(__file__).parents[2] / "drivers" / "maps"

BASE = """
schema = "soakcal-register-map/1"
kind = "chamber"
name = "bench"
[registers.process_c]
address = 1
type = "int16"
scale = 10
[registers.setpoint_c]
address = 2
type = "int16"
scale = 10
access = "rw"
[registers.trigger]
address = 3
type = "uint16"
access = "w"
[registers.mode]
address = 4
type = "uint16"
"""


def _load(tmp_path: Path, text: str) -> Any:
    path = tmp_path / "bench.toml"
    path.write_text(text)
    return load_map(path)


def _config(sim: Any, chamber_map: str) -> dict[str, Any]:
    return {"name": "bench",
            "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": chamber_map},
            "turntable": {"url": sim.table_url, "map": sim.table_map},
            "sensors": [{"url": sim.sensor_url}]}


def _by(checks: list[Check], name: str) -> Check:
    return next(c for c in checks if c.device == "chamber" and c.check == name)


# --- the map file ----------------------------------------------------------------------


def test_a_forgotten_working_setpoint_is_refused_naming_absent_roles(tmp_path: Path) -> None:
    with pytest.raises(MapError) as err:
        _load(tmp_path, BASE)
    assert "registers.working_setpoint_c: missing" in str(err.value)
    assert 'absent_roles = ["working_setpoint_c"]' in str(err.value)


@pytest.mark.parametrize(("extra", "key", "words"), [
    ('absent_roles = ["process_c"]\n', "absent_roles[0]", "cannot be absent"),
    ('absent_roles = ["working_setpoint_c", "ramp_c_per_min", "setpoint_c"]\n',
     "absent_roles[2]", "cannot be absent"),
])
def test_only_the_optional_roles_can_be_absent(tmp_path: Path, extra: str, key: str,
                                                words: str) -> None:
    with pytest.raises(MapError) as err:
        _load(tmp_path, extra + BASE)
    assert f": {key}: " in str(err.value) and words in str(err.value)


def test_a_role_both_mapped_and_absent_is_refused(tmp_path: Path) -> None:
    text = 'absent_roles = ["working_setpoint_c", "ramp_c_per_min"]\n' + BASE + """
[registers.working_setpoint_c]
address = 5
type = "int16"
"""
    with pytest.raises(MapError, match=r"absent_roles\[0\]: working_setpoint_c is listed as "
                                       r"absent but \[registers.working_setpoint_c\] maps it"):
        _load(tmp_path, text)


ABSENT = 'absent_roles = ["working_setpoint_c", "ramp_c_per_min"]\n'


@pytest.mark.parametrize(("sequence", "key", "words"), [
    ('[[sequence.set_setpoint]]\nregister = "trigger"\nvalue = 1\n',
     "sequence.set_setpoint", 'exactly one step with from = "setpoint_c"'),
    ('[[sequence.set_setpoint]]\nregister = "trigger"\nvalue = 1\nfrom = "setpoint_c"\n',
     "sequence.set_setpoint[0]", "exactly one of value"),
    ('[[sequence.set_setpoint]]\nregister = "mode"\nvalue = 1\n',
     "registers.mode.access", "the driver writes this register"),
    ('[[sequence.set_setpoint]]\nregister = "trigger"\nvalue = 70000\n',
     "sequence.set_setpoint[0].value", "does not fit register trigger"),
    ('[[sequence.set_setpoint]]\nregister = "setpoint_c"\nfrom = "ramp_c_per_min"\n',
     "sequence.set_setpoint[0].from", 'expected "setpoint_c"'),
    ('[[sequence.start_profile]]\nregister = "trigger"\nvalue = 1\n',
     "sequence.start_profile", "unknown sequence"),
    ('[[sequence.set_setpoint]]\nregister = "trigger"\nvalu = 1\n',
     "sequence.set_setpoint[0].valu", "unknown key"),
])
def test_a_wrong_sequence_is_refused_naming_its_key(tmp_path: Path, sequence: str, key: str,
                                                     words: str) -> None:
    with pytest.raises(MapError) as err:
        _load(tmp_path, ABSENT + BASE + sequence)
    assert f": {key}: " in str(err.value) and words in str(err.value), str(err.value)


def test_a_sequence_loads_in_its_order(tmp_path: Path) -> None:
    m = _load(tmp_path, ABSENT + BASE + """
[[sequence.set_setpoint]]
register = "trigger"
value = 3
[[sequence.set_setpoint]]
register = "setpoint_c"
from = "setpoint_c"
[[sequence.set_setpoint]]
register = "trigger"
value = 1
""")
    steps = m.sequences["set_setpoint"]
    assert [(s.register, s.value, s.source) for s in steps] == [
        ("trigger", 3.0, None), ("setpoint_c", None, "setpoint_c"), ("trigger", 1.0, None)]
    assert m.working_setpoint_c is None and m.ramp_c_per_min is None


def test_rig_validate_accepts_the_new_keys_and_names_a_bad_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from service.cli import main

    assert main(["rig", "validate", "watlow-f4"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("OK: watlow-f4 — Watlow Series F4")
    assert ("5 registers, no working_setpoint_c, no ramp_c_per_min, sequence set_setpoint "
            "of 2 writes, 7 undocumented points listed)") in out
    bad = tmp_path / "f4.toml"
    bad.write_text((MAPS / "watlow-f4.toml").read_text().replace(
        'register = "terminate_profile"', 'register = "terminate"'))
    assert main(["rig", "validate", str(bad)]) == 2
    assert "sequence.set_setpoint[0].register: names no register" in capsys.readouterr().err


# --- over the wire -----------------------------------------------------------------------


async def test_a_controller_without_wsp_or_ramp_reads_none_and_refuses_a_ramp() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="csz-ezt-430i") as sim, \
            open_rig(_config(sim, "csz-ezt-430i"), clock) as rig:
        st = await rig.chamber.read_status()
        assert st.working_setpoint_c is None and st.ramp_c_per_min == 0.0
        assert st.process_c == pytest.approx(23.0, abs=0.2)
        await rig.chamber.set_ramp_rate(0.0)  # a step: nothing to write, accepted
        with pytest.raises(ValueOutOfRange) as err:
            await rig.chamber.set_ramp_rate(1.0)
        assert "absent_roles" in str(err.value) and "ramp_c_per_min = 0" in str(err.value)
        await rig.chamber.set_setpoint(40.0)
        assert sim.chamber.setpoint_c == 40.0
        await clock.sleep(600.0)
        # No ramp register: the air goes as fast as the chamber can (5 °C/min in the twin).
        assert (await rig.chamber.read_status()).process_c == pytest.approx(40.0, abs=0.5)


@pytest.mark.parametrize(("write", "follows"), [("single", True), ("multiple", False)])
async def test_an_ezt_ignoring_fc16_moves_only_with_single_writes(
        tmp_path: Path, write: str, follows: bool) -> None:
    path = tmp_path / "ezt.toml"
    path.write_text((MAPS / "csz-ezt-430i.toml").read_text().replace(
        'write = "single"', f'write = "{write}"'))
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path),
                             controller=ControllerSetup(single_writes_only=True)) as sim, \
            open_rig(_config(sim, str(path)), clock) as rig:
        await rig.chamber.set_setpoint(30.0)
        assert sim.chamber.setpoint_c == (30.0 if follows else 23.0)
        assert (await rig.chamber.read_status()).setpoint_c == (30.0 if follows else 23.0)


@pytest.mark.parametrize("with_sequence", [True, False])
async def test_an_f4_running_a_profile_follows_only_the_sequenced_setpoint(
        tmp_path: Path, with_sequence: bool) -> None:
    text = (MAPS / "watlow-f4.toml").read_text()
    if not with_sequence:  # the same registers, the setpoint written alone
        head, _, rest = text.partition("# Every setpoint change")
        text = head + rest[rest.index("[registers.process_c]"):]
    path = tmp_path / "f4.toml"
    path.write_text(text)
    assert bool(load_map(path).sequences) is with_sequence
    clock = VirtualClock()
    setup = ControllerSetup(profile_owns_setpoint=("terminate_profile", 1))
    async with start_sim_rig(clock, seed=4, chamber_map=str(path), controller=setup) as sim, \
            open_rig(_config(sim, str(path)), clock) as rig:
        await rig.chamber.set_setpoint(35.0)
        # The static setpoint reads back either way; only the terminated profile lets the
        # controller follow it.
        assert (await rig.chamber.read_status()).setpoint_c == 35.0
        assert sim.chamber.setpoint_c == (35.0 if with_sequence else 23.0)


# --- rig check ---------------------------------------------------------------------------


async def test_rig_check_says_why_the_ramp_is_not_timed_without_those_roles() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="csz-ezt-430i") as sim:
        checks = await check_rig(_config(sim, "csz-ezt-430i"), move=True, clock=clock)
        assert sim.chamber.setpoint_c == pytest.approx(23.0)  # the nudge was put back
    assert passed(checks), format_report("ezt", checks)
    status = _by(checks, "status").detail
    assert "no WSP register" in status and "no ramp register (steps)" in status
    ramp = _by(checks, "ramp")
    assert ramp.status == "skip"
    assert "csz-ezt-430i.toml lists ramp_c_per_min under absent_roles" in ramp.detail
    assert _by(checks, "setpoint_nudge").status == "pass"
    assert _by(checks, "pv_vs_die").status == "pass"
    follows = _by(checks, "pv_follows")
    assert follows.status == "pass" and "toward 23.5 °C" in follows.detail
    assert "back toward 23.0 °C" in follows.detail


@pytest.mark.parametrize(("start_c", "words"), [
    (23.0, "the controller does not follow the setpoint it was given"),
    # Drifting back to room temperature in standby: up with the nudge, never back.
    (-20.0, "it went on one way, as a chamber drifting in standby does"),
])
async def test_an_ezt_in_standby_fails_pv_follows(start_c: float, words: str) -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="csz-ezt-430i", start_c=start_c,
                             controller=ControllerSetup(mode="standby")) as sim:
        sim.chamber.ambient_c = 23.0  # the room: a chamber left cold drifts up towards it
        checks = await check_rig(_config(sim, "csz-ezt-430i"), move=True, clock=clock)
    follows = _by(checks, "pv_follows")
    assert follows.status == "fail" and words in follows.detail, follows
    assert "standby" in follows.fix


async def test_an_f4_profile_owning_the_setpoint_fails_pv_follows_without_the_sequence(
        tmp_path: Path) -> None:
    text = (MAPS / "watlow-f4.toml").read_text()
    head, _, rest = text.partition("# Every setpoint change")
    path = tmp_path / "f4.toml"
    path.write_text(head + rest[rest.index("[registers.process_c]"):])
    clock = VirtualClock()
    # The profile status reads "constant" here, so only the PV can tell.
    setup = ControllerSetup(profile_owns_setpoint=("terminate_profile", 1))
    async with start_sim_rig(clock, seed=4, chamber_map=str(path), controller=setup) as sim:
        checks = await check_rig(_config(sim, str(path)), move=True, clock=clock)
    follows = _by(checks, "pv_follows")
    assert follows.status == "fail" and "[[sequence.set_setpoint]]" in follows.fix


async def test_rig_check_without_wsp_but_with_a_ramp_says_it_cannot_time_it(
        tmp_path: Path) -> None:
    path = tmp_path / "nowsp.toml"
    path.write_text((MAPS / "eurotherm-3216.toml").read_text().replace(
        "[registers.working_setpoint_c]", "[registers.unused_wsp]").replace(
        'name = "eurotherm-3216"', 'name = "nowsp"\nabsent_roles = ["working_setpoint_c"]'))
    assert CHAMBER_MAPS["eurotherm-3216"].working_setpoint_c is not None
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path)) as sim:
        sim.chamber.running = True
        checks = await check_rig(_config(sim, str(path)), move=True, clock=clock)
    assert passed(checks), format_report("nowsp", checks)
    assert "no working-setpoint register" in _by(checks, "ramp").detail


async def test_a_ten_times_scaled_ezt_is_still_caught_without_wsp() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="csz-ezt-430i",
                             controller=ControllerSetup(decimals=0)) as sim:
        checks = await check_rig(_config(sim, "csz-ezt-430i"), move=True, clock=clock)
    die = _by(checks, "pv_vs_die")
    assert die.status == "fail" and "×10" in die.detail
    assert "csz-ezt-430i.toml" in die.fix


def test_soakcal_sim_refuses_a_profile_register_the_map_lacks(
        capsys: pytest.CaptureFixture[str]) -> None:
    from simulators.cli import run_sim

    assert run_sim(["--chamber-map", "watlow-f4", "--profile-owns-setpoint", "terminate=1",
                    "--duration-s", "0"]) == 2
    assert "map watlow-f4 names no register 'terminate'" in capsys.readouterr().err
    assert run_sim(["--chamber-map", "watlow-f4", "--profile-owns-setpoint",
                    "terminate_profile=yes", "--duration-s", "0"]) == 2
    assert "expected REGISTER=NUMBER" in capsys.readouterr().err


async def test_an_fc16_setpoint_the_controller_ignores_names_single_writes(
        tmp_path: Path) -> None:
    path = tmp_path / "ezt-fc16.toml"
    path.write_text((MAPS / "csz-ezt-430i.toml").read_text().replace(
        'write = "single"', 'write = "multiple"'))
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map=str(path),
                             controller=ControllerSetup(single_writes_only=True)) as sim:
        checks = await check_rig(_config(sim, str(path)), move=True, clock=clock)
    nudge = _by(checks, "setpoint_nudge")
    assert nudge.status == "fail" and "wrote 23.50 °C, read 23.00 °C" in nudge.detail
    assert 'set `write = "single"` on register `setpoint_c` in ezt-fc16.toml' in nudge.fix


async def test_an_f4_left_running_a_profile_fails_its_check() -> None:
    clock = VirtualClock()
    setup = ControllerSetup(profile_owns_setpoint=("terminate_profile", 1),
                            holds=(("profile_status", 2),))
    async with start_sim_rig(clock, seed=4, chamber_map="watlow-f4", controller=setup) as sim:
        checks = await check_rig(_config(sim, "watlow-f4"), move=True, clock=clock)
        # The nudge went through the sequence: the profile is terminated, SP followed back.
        assert sim.chamber.setpoint_c == pytest.approx(23.0)
    profile = _by(checks, "register:profile_status")
    assert profile.status == "fail" and "reads 2" in profile.detail
    assert "terminate the profile" in profile.fix


class _RecordingLink:
    """Records every write in order (what goes on the wire, by register address)."""

    device = "chamber"

    def __init__(self) -> None:
        self.writes: list[tuple[int, float]] = []

    async def write_field(self, f: Any, value: float, *, idempotent: bool = False) -> None:
        f.encode(value)  # a value the register cannot hold fails here, as on the wire
        self.writes.append((f.address, value))


async def test_sequences_write_in_file_order_with_the_commanded_value(tmp_path: Path) -> None:
    from drivers.chamber import ModbusChamber

    m = _load(tmp_path, 'absent_roles = ["working_setpoint_c", "ramp_c_per_min"]\n' + BASE + """
[registers.profile_rate]
address = 10
type = "uint16"
scale = 10
access = "rw"
[[sequence.set_ramp_rate]]
register = "trigger"
value = 2
[[sequence.set_ramp_rate]]
register = "profile_rate"
from = "ramp_c_per_min"
[[sequence.set_setpoint]]
register = "setpoint_c"
from = "setpoint_c"
[[sequence.set_setpoint]]
register = "trigger"
value = 5
""")
    link = _RecordingLink()
    chamber = ModbusChamber(link, m)  # type: ignore[arg-type]
    await chamber.set_ramp_rate(1.5)
    await chamber.set_setpoint(-20.0)
    assert link.writes == [(3, 2.0), (10, 1.5), (2, -20.0), (3, 5.0)]
    # The rate's register holds tenths: 0.04 °C/min would be written as 0, refused first.
    with pytest.raises(ValueOutOfRange, match="register 10: it would hold 0"):
        await chamber.set_ramp_rate(0.04)
    assert len(link.writes) == 4


async def test_a_fahrenheit_ezt_is_named_with_only_the_registers_it_has() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, chamber_map="csz-ezt-430i",
                             controller=ControllerSetup(units="F")) as sim:
        checks = await check_rig(_config(sim, "csz-ezt-430i"), move=True, clock=clock)
    die = _by(checks, "pv_vs_die")
    assert die.status == "fail" and "the controller reads in °F" in die.detail
    assert "`offset = -17.7778`, likewise setpoint_c" in die.fix
    assert "working_setpoint_c" not in die.fix
