"""Recording format v1 (docs/recording.md): the rules the readers apply."""

from pathlib import Path

import numpy as np
import pytest

from calibration.errors import RecordingError
from calibration.recording import (
    Recording,
    parse_recording,
    read_recording,
    recording_text,
    write_recording,
)

GOOD = (
    "t_s,step,setpoint_c,chamber_c,sensor_c,position,ref_x,ref_y,ref_z,ax,ay,az,n\n"
    "5570.0,0,-40,-39.999,-38.75,0,0,0,1,0.00421993386,0.0197724144,0.992438681,200\n"
    "5610.0,0,-40,-40.012,-38.81,1,0,0.707106781,0.707106781,0.00398012,0.72305513,"
    "0.70311872,200\n"
)


def _rows(*rows: str, header: str = "t_s,chamber_c,ax,ay,az") -> str:
    return header + "\n" + "\n".join(rows) + "\n"


def test_the_spec_example_reads() -> None:
    rec = parse_recording(GOOD, "ex.csv")
    assert len(rec) == 2
    assert rec.has_reference and rec.has_temperature
    assert rec.temperature_source == "sensor_c"  # sensor_c wins where present and filled
    np.testing.assert_allclose(rec.temperature_c(), [-38.75, -38.81])
    np.testing.assert_allclose(rec.raw_g[1], [0.00398012, 0.72305513, 0.70311872])


def _reject(text: str, *, range_g: float = 8.0) -> RecordingError:
    with pytest.raises(RecordingError) as info:
        parse_recording(text, "bad.csv", range_g=range_g)
    err = info.value
    assert "bad.csv" in str(err)
    return err


def test_non_numeric_cell_names_file_line_and_column() -> None:
    err = _reject(_rows("0,25,0,0,1", "1,25,0,abc,1"))
    assert (err.path, err.line, err.column) == ("bad.csv", 3, "ay")
    assert "bad.csv:3: column 'ay'" in str(err) and "abc" in str(err)


@pytest.mark.parametrize("missing", ["t_s", "ax", "ay", "az"])
def test_missing_required_column_is_named(missing: str) -> None:
    header = ",".join(c for c in ("t_s", "chamber_c", "ax", "ay", "az") if c != missing)
    row = ",".join(["0"] * 4)
    err = _reject(_rows(row, header=header))
    assert (err.line, err.column) == (1, missing)


def test_missing_temperature_column_is_rejected() -> None:
    err = _reject(_rows("0,0,0,1", header="t_s,ax,ay,az"))
    assert err.line == 1 and err.column in ("chamber_c", "sensor_c")


def test_time_going_backwards_names_the_row() -> None:
    err = _reject(_rows("0,25,0,0,1", "10,25,0,0,1", "9.5,25,0,0,1"))
    assert (err.line, err.column) == (4, "t_s")
    assert "backwards" in str(err)


def test_equal_times_are_allowed() -> None:
    assert len(parse_recording(_rows("0,25,0,0,1", "0,25,0,1,0"))) == 2


def test_reading_outside_the_sensor_range_names_the_cell() -> None:
    err = _reject(_rows("0,25,0,0,1", "1,25,0,0,2.5"), range_g=2.0)
    assert (err.line, err.column) == (3, "az")
    assert "range" in str(err)
    assert len(parse_recording(_rows("0,25,0,0,1", "1,25,0,0,2.5"), range_g=8.0)) == 2


def test_empty_required_value_and_short_row_are_rejected() -> None:
    err = _reject(_rows("0,25,0,,1"))
    assert (err.line, err.column) == (2, "ay")
    err = _reject(_rows("0,25,0,1"))
    assert err.line == 2


def test_unknown_columns_are_kept_with_their_text() -> None:
    text = _rows("0,25,0,0,1,run-A", "1,25,0,1,0,run-B", header="t_s,chamber_c,ax,ay,az,operator")
    rec = parse_recording(text)
    assert rec.header[-1] == "operator"
    assert rec.cells is not None and [r[-1] for r in rec.cells] == ["run-A", "run-B"]
    sub = rec.subset(np.array([False, True]))
    assert sub.cells == [["1", "25", "0", "1", "0", "run-B"]]


def test_steps_from_the_step_column_then_setpoint_then_plateaus() -> None:
    # The step column wins even when the setpoint says otherwise.
    with_step = parse_recording(_rows(
        "0,1,-40,-40,0,0,1", "1,1,-30,-40,0,0,1", "2,2,-30,-30,0,0,1",
        header="t_s,step,setpoint_c,chamber_c,ax,ay,az"))
    assert list(with_step.steps()) == [1, 1, 2]

    from_setpoint = parse_recording(_rows(
        "0,-40,-40.1,0,0,1", "1,-40,-39.9,0,0,1", "2,-30,-35,0,0,1", "3,-30,-30.1,0,0,1",
        header="t_s,setpoint_c,chamber_c,ax,ay,az"))
    assert list(from_setpoint.steps()) == [0, 0, 1, 1]

    from_plateaus = parse_recording(_rows(
        "0,-40.0,0,0,1", "1,-40.1,0,0,1", "2,-39.9,0,0,1",
        "3,-30.0,0,0,1", "4,-30.2,0,0,1", "5,-20.1,0,0,1"))
    assert list(from_plateaus.steps()) == [0, 0, 0, 1, 1, 2]
    assert list(from_plateaus.positions()) == [0, 1, 2, 0, 1, 0]


def test_no_temperature_at_all_is_one_step_at_unknown_temperature(tmp_path: Path) -> None:
    rec = Recording.from_columns({"t_s": [0, 1], "chamber_c": [np.nan, np.nan],
                                  "ax": [0, 0], "ay": [0, 1], "az": [1, 0]})
    out = tmp_path / "imp.csv"
    write_recording(out, rec)
    assert out.read_text().splitlines()[1].split(",")[1] == ""  # empty cell, not 'nan'
    back = read_recording(out)
    assert not back.has_temperature
    assert list(back.steps()) == [0, 0]


def test_a_gap_in_a_temperature_column_is_an_error() -> None:
    err = _reject(_rows("0,25,0,0,1", "1,,0,0,1"))
    assert (err.line, err.column) == (3, "chamber_c")


def test_write_then_read_round_trips(tmp_path: Path) -> None:
    rec = parse_recording(GOOD)
    out = tmp_path / "sub" / "rt.csv"
    write_recording(out, rec)
    back = read_recording(out)
    for name in rec.header:
        np.testing.assert_array_equal(back.columns[name], rec.columns[name])
    assert recording_text(back) == recording_text(rec)


def test_nothing_is_written_when_the_input_is_rejected(tmp_path: Path) -> None:
    out = tmp_path / "never.csv"
    with pytest.raises(RecordingError):
        write_recording(out, {"t_s": [1.0, 0.0], "chamber_c": [20, 20],
                              "ax": [0, 0], "ay": [0, 0], "az": [1, 1]})
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_missing_file_and_empty_file(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="not found"):
        read_recording(tmp_path / "nope.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(RecordingError, match="header"):
        read_recording(tmp_path / "empty.csv")


@pytest.mark.parametrize("slow_path", [False, True])
def test_without_copy_through_a_numeric_file_keeps_no_text(tmp_path: Path, slow_path: bool) -> None:
    """calibrate and diagnose read with raw_cells=False: the numbers stay, the text goes;
    a text column (ref_tol_deg is read from the cells) keeps the cells."""
    rows = ["t_s,sensor_c,ax,ay,az", "0,20.0,0.0,0.0,1.0", "1,20.1,0.0,0.0,1.0"]
    if slow_path:  # a quoted cell sends the file to the row-by-row reader
        rows[2] = '1,"20.1",0.0,0.0,1.0'
    path = tmp_path / "r.csv"
    path.write_text("\n".join(rows) + "\n")
    kept = read_recording(path)
    lean = read_recording(path, raw_cells=False)
    assert kept.cells is not None and lean.cells is None
    assert lean.columns["sensor_c"].tolist() == [20.0, 20.1]
    path.write_text("\n".join([rows[0] + ",ref_tol_deg"] + [r + ",2" for r in rows[1:]]) + "\n")
    assert read_recording(path, raw_cells=False).cells is not None
