"""Turntable maps v2: a drive per axis (unit ids), move/home/stop sequences, the Leadshine
RS485 PR0 profile, the twin playing such drives over Modbus, and the hand-axis geometry."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from calibration.schedules import get_schedule
from drivers.clock import VirtualClock
from drivers.geometry import (
    UnreachablePose,
    angles_for_hand_axis,
    hand_axis_unreachable,
    reference_for_angles,
)
from drivers.registermaps import MAPS_DIR, MapError, describe_map, load_map
from drivers.turntable import ModbusTurntable
from service.rig_check import check_rig, format_report, passed
from simulators.rig import connect_rig, start_sim_rig

LEADSHINE = MAPS_DIR / "leadshine-rs485-pr.toml"
# A homing start for the twin's test only: the value written to the PR control word to
# home is NOT in the manual pages read (the shipped map says so and has no home sequence).
TEST_HOME = '''
[[sequence.home]]
register = "pr_control"
value = 32
note = "test-only value"

[registers.pr_control]
address = 24578
type = "uint16"
access = "w"
'''


def _variant(tmp_path: Path, old: str, new: str, extra: str = "") -> Path:
    text = LEADSHINE.read_text()
    assert old in text
    p = tmp_path / "drive.toml"
    p.write_text(text.replace(old, new) + extra)
    return p


def test_the_leadshine_profile_loads_and_says_what_it_lacks() -> None:
    m = load_map(LEADSHINE)
    assert m.unit_ids == (1, 2) and m.command is None
    assert m.position_deg is not None and m.position_deg.address == 0x1014
    assert (m.in_position_bit, m.moving_bit, m.homed_bit) == (4, 2, 6)
    assert [s.register for s in m.sequences["move"]][-1] == "pr0_trigger"
    assert "home" not in m.sequences and "stop" not in m.sequences  # not documented
    line = describe_map(m)
    assert "unit ids 1/2" in line and "no position_deg" not in line
    assert "sequence move of 7 writes" in line and "7 undocumented points" in line
    assert any("homing and stop" in n for n in m.undocumented)


@pytest.mark.parametrize(("old", "new", "extra", "key"), [
    ("unit_ids = [1, 2]", "unit_ids = [1, 1]", "", "axes.unit_ids"),
    ("unit_ids = [1, 2]", "unit_ids = [1, 0]", "", "axes.unit_ids[1]"),
    ("unit_ids = [1, 2]", "unit_ids = [1]", "", "axes.unit_ids"),
    (', 6 = "homed" }', " }", TEST_HOME, "registers.status.bits"),
    ("[registers.position_deg]", "[registers.feedback]", "", "registers.position_deg"),
    ('kind = "turntable"', 'kind = "turntable"\nabsent_roles = ["status"]', "",
     "absent_roles[0]"),
    ('kind = "turntable"', 'kind = "turntable"\nabsent_roles = ["position_deg"]', "",
     "absent_roles[0]"),
    ('from = "target_deg"', "value = 3", "", "sequence.move"),
])
def test_a_wrong_drive_map_is_refused_naming_the_key(tmp_path: Path, old: str, new: str,
                                                     extra: str, key: str) -> None:
    with pytest.raises(MapError, match=re.escape(f": {key}: ")):
        load_map(_variant(tmp_path, old, new, extra))


def test_a_home_sequence_writes_constants_only(tmp_path: Path) -> None:
    bad = TEST_HOME.replace("value = 32", 'from = "target_deg"')
    with pytest.raises(MapError, match=r"sequence\.home\[0\]\.from: this sequence writes "
                                       "constants only"):
        load_map(_variant(tmp_path, "[limits]", "[limits]", bad))


def _config(sim, table_map: str, **table) -> dict:  # type: ignore[no-untyped-def]
    return {"name": "bench",
            "chamber": {"driver": "modbus", "url": sim.chamber_url, "map": sim.chamber_map},
            "turntable": {"url": sim.table_url, "map": table_map, **table},
            "sensors": [{"url": sim.sensor_url}]}


async def test_rig_check_moves_a_drive_per_axis_over_the_wire() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=4, table_map="leadshine-rs485-pr") as sim:
        checks = await check_rig(_config(sim, "leadshine-rs485-pr"), move=True, clock=clock)
        # Moved on unit 1 (the outer axis) and put back; unit 2's axis never moved.
        assert sim.table.true_angles_deg() == pytest.approx((0.0, 0.0), abs=0.02)
    assert passed(checks), format_report("bench", checks)
    move = next(c for c in checks if c.check == "table_move")
    assert move.status == "pass" and "axis 0 0.00°" in move.detail


async def test_each_axis_is_addressed_on_its_own_unit_id() -> None:
    """The trigger of axis 1 goes to unit 2 only: unit 1's axis stays where it is."""
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=1, table_map="leadshine-rs485-pr") as sim:
        chamber, table, accel = await connect_rig(sim, clock)
        try:
            await table.move_to((0.0, -45.0))
            await clock.sleep(10.0)
            st = await table.read_status()
            assert sim.table.true_angles_deg() == pytest.approx((0.0, -45.0), abs=0.02)
            # Read back from each drive's feedback position (pulses → degrees).
            assert st.in_position and not st.moving and st.faults == ()
            assert st.angles_deg == pytest.approx((0.0, -45.0), abs=0.04)
            assert await table.park() == "no stop in the map (undocumented), sent to (0, 0)°"
        finally:
            await table.close()
            await chamber.link.close()
            await accel.close()


async def test_without_a_readback_the_commanded_angles_are_reported(tmp_path: Path) -> None:
    path = _variant(tmp_path, "[registers.position_deg]", "[registers.feedback]")
    path.write_text(path.read_text().replace('kind = "turntable"', 'kind = "turntable"\n'
                                             'absent_roles = ["position_deg"]'))
    assert "no position_deg" in describe_map(load_map(path))
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=1, table_map=str(path)) as sim:
        chamber, table, accel = await connect_rig(sim, clock)
        try:
            await table.move_to((30.0, 0.0))
            await clock.sleep(10.0)
            st = await table.read_status()
            # 30° is 833.3 pulses: the drive went to 833 (29.988°); the driver says 30.
            assert st.in_position and st.angles_deg == (30.0, 0.0)
            assert sim.table.true_angles_deg()[0] == pytest.approx(29.988, abs=1e-3)
        finally:
            await table.close()
            await chamber.link.close()
            await accel.close()


async def test_homing_runs_each_drive_to_its_switch_and_reports_homed(tmp_path: Path) -> None:
    path = _variant(tmp_path, "[limits]", "[limits]", TEST_HOME)
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=2, table_map=str(path)) as sim:
        chamber, table, accel = await connect_rig(sim, clock)
        try:
            assert isinstance(table, ModbusTurntable)
            sim.table.move_axis(0, 30.0)  # wherever the table was at power-up
            await clock.sleep(10.0)
            assert (await table.read_status()).homed is False
            await table.home()
            await clock.sleep(0.5)
            assert (await table.read_status()).homed is False  # still running home
            await clock.sleep(10.0)
            st = await table.read_status()
            assert st.homed is True and st.in_position
            assert sim.table.true_angles_deg() == pytest.approx((0.0, 0.0))
        finally:
            await table.close()
            await chamber.link.close()
            await accel.close()


async def test_a_map_without_homing_refuses_to_home() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=2, table_map="leadshine-rs485-pr") as sim:
        chamber, table, accel = await connect_rig(sim, clock)
        try:
            with pytest.raises(Exception, match=r"no \[\[sequence.home\]\]: home the table "
                                                "at the drive"):
                await table.home()
        finally:
            await table.close()
            await chamber.link.close()
            await accel.close()


# --- hand axis geometry ---------------------------------------------------------------
@pytest.mark.parametrize("ref", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0),
                                 (0, -1, 0)])
def test_every_face_is_reached_with_the_hand_axis_on_quarter_steps(ref: tuple) -> None:
    motor, hand = angles_for_hand_axis(np.array(ref, float), (0, 90, 180, 270), 180.0)
    assert hand % 90 == 0
    assert reference_for_angles((motor, hand)) == pytest.approx(ref, abs=1e-9)


def test_a_free_hand_axis_reaches_a_corner_and_quarter_steps_do_not() -> None:
    corner = np.array([1.0, 1.0, 1.0]) / np.sqrt(3)
    pose = angles_for_hand_axis(corner, None, 180.0)
    assert reference_for_angles(pose) == pytest.approx(corner)
    with pytest.raises(UnreachablePose, match=r"needs motor 35.3° with hand -45.0° or motor "
                                              r"144.7° with hand 135.0°; the hand axis stops "
                                              r"only at 0°, 90°, 180°, 270°"):
        angles_for_hand_axis(corner, (0, 90, 180, 270), 180.0)


def test_the_other_pose_is_taken_when_the_motor_range_needs_it() -> None:
    # -z up: (0°, 180°) — with hand steps 0/180 only, and a motor of ±90°.
    assert angles_for_hand_axis(np.array([0, 0, -1.0]), (0, 180), 90.0) == (0.0, 180.0)
    with pytest.raises(UnreachablePose, match=r"the motor reaches ±30°"):
        angles_for_hand_axis(np.array([0, 1.0, 0]), None, 30.0)


def test_the_schedules_unreachable_positions_are_listed_with_why() -> None:
    assert hand_axis_unreachable(get_schedule("six"), (0, 90, 180, 270), 180.0) == []
    bad = hand_axis_unreachable(get_schedule("cube14"), (0, 90, 180, 270), 180.0)
    assert len(bad) == 8 and all("hand axis stops only at" in why for _, why in bad)


class _Bus:
    """Two drives' answers by unit id: (feedback pulses, motion state word)."""

    def __init__(self, answers: dict[int, tuple[float, int]]) -> None:
        self.answers, self.device_id, self.device, self.asked = answers, 1, "turntable", []

    async def read_fields(self, fields: list, max_gap_words: int = 0) -> list[float]:
        self.asked.append((self.device_id, [f.address for f in fields]))
        pulses, word = self.answers[self.device_id]
        return [fields[0].decode(fields[0].encode(pulses / fields[0].scale)), float(word)]


async def test_a_drive_reporting_a_fault_is_named_by_axis() -> None:
    # Unit 2's motion state: bit 0 faulty, bit 1 enabled, bit 4 command completed.
    bus = _Bus({1: (0.0, 0b10010), 2: (2500.0, 0b10011)})
    table = ModbusTurntable(bus, load_map(LEADSHINE))  # type: ignore[arg-type]
    st = await table.read_status()
    assert st.faults == ("axis 1: fault",) and st.in_position
    assert st.angles_deg == pytest.approx((0.0, 90.0))  # 2500 pulses at 27.78 per degree
    assert bus.asked == [(1, [0x1014, 0x1003]), (2, [0x1014, 0x1003])]
    assert bus.device_id == 1  # restored after each request


class _Motor:
    n_axes = 1

    def __init__(self) -> None:
        self.moves: list[tuple[float, ...]] = []

    async def move_to(self, angles: tuple[float, ...]) -> None:
        self.moves.append(angles)

    async def read_status(self):  # type: ignore[no-untyped-def]
        from drivers.protocols import TurntableStatus

        return TurntableStatus(self.moves[-1] if self.moves else (0.0,), True, False)


class _Board:
    def __init__(self, campaign: bool) -> None:
        self.campaign, self.published, self.state_ = campaign, [], "pending"

    def publish(self, ref, reason=None, instruction=None):  # type: ignore[no-untyped-def]
        if not self.campaign:
            return None
        self.published.append(instruction)
        return {"instruction": instruction}

    def state(self) -> str:
        return self.state_

    def accept(self) -> None:
        self.state_ = "accepted"


async def test_the_hand_axis_is_asked_only_when_it_changes_and_only_in_a_campaign() -> None:
    from drivers.manual_table import HandAxisTurntable

    motor, board = _Motor(), _Board(campaign=True)
    table = HandAxisTurntable(motor, board)
    await table.move_to((0.0, 90.0))
    assert board.published == ["turn the hand axis to 90° and lock it (the motorised axis "
                               "moves by itself)"]
    assert not (await table.read_status()).in_position  # the operator has not confirmed
    board.state_ = "confirmed"
    st = await table.read_status()
    assert st.in_position and st.angles_deg == (0.0, 90.0) and board.state_ == "accepted"
    await table.move_to((45.0, 90.0))  # the motor alone
    assert len(board.published) == 1 and motor.moves[-1] == (45.0,)
    assert (await table.read_status()).in_position
    idle = HandAxisTurntable(_Motor(), _Board(campaign=False))  # rig check: no campaign
    await idle.move_to((10.0, 0.0))
    assert (await idle.read_status()).in_position
