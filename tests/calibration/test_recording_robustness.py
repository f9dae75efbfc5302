"""Bad recordings are refused with file, line and column: no traceback, nothing written."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from calibration.errors import RecordingError
from calibration.recording import (
    check_output_path,
    parse_recording,
    read_recording,
    write_recording,
)

HEADER = "t_s,chamber_c,ref_x,ref_y,ref_z,ax,ay,az,n,sd_x,sd_y,sd_z"
GOOD = "0,20,0,0,1,0.001,0.002,1.001,200,0.0001,0.0001,0.0001"


def _row(**overrides: str) -> str:
    cells = dict(zip(HEADER.split(","), GOOD.split(","), strict=True))
    cells.update(overrides)
    return ",".join(cells.values())


def test_good_row_reads() -> None:
    rec = parse_recording(f"{HEADER}\n{GOOD}\n", "r.csv")
    assert len(rec) == 1


@pytest.mark.parametrize(
    ("overrides", "column", "words"),
    [
        ({"chamber_c": "293.15"}, "chamber_c", "kelvin"),
        ({"chamber_c": "-150"}, "chamber_c", "plausible temperature"),
        ({"n": "0"}, "n", "whole number"),
        ({"n": "-3"}, "n", "whole number"),
        ({"sd_x": "-0.1"}, "sd_x", "negative"),
        ({"ref_z": "1000"}, "ref_x", "magnitude 1000"),
        ({"ref_y": ""}, "ref_y", "incomplete"),
        ({"ax": "1_6384"}, "ax", "not a number"),
        ({"ax": "\u0661\u0662"}, "ax", "not a number"),  # Arabic-Indic digits
        ({"ax": "nan"}, "ax", "not a number"),
        ({"ax": "1" * 100}, "ax", "not a number"),
    ],
)
def test_implausible_values_are_refused_with_line_and_column(
    overrides: dict[str, str], column: str, words: str
) -> None:
    text = f"{HEADER}\n{GOOD}\n{_row(**overrides)}\n"
    with pytest.raises(RecordingError) as err:
        parse_recording(text, "r.csv")
    assert err.value.line == 3
    assert err.value.column == column
    assert words in err.value.message
    assert len(str(err.value)) < 300  # a 1 MB cell is never echoed back


def test_semicolon_separated_file_gets_a_hint() -> None:
    text = HEADER.replace(",", ";") + "\n" + GOOD.replace(",", ";") + "\n"
    with pytest.raises(RecordingError, match="semicolon-separated"):
        parse_recording(text, "r.csv")


def test_directory_and_device_are_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="is a directory"):
        read_recording(tmp_path)
    if os.path.exists("/dev/zero"):
        with pytest.raises(RecordingError, match="not a regular file"):
            read_recording("/dev/zero")


def test_output_equal_to_input_is_refused(tmp_path: Path) -> None:
    src = tmp_path / "r.csv"
    src.write_text(f"{HEADER}\n{GOOD}\n")
    with pytest.raises(RecordingError, match="overwrite the input"):
        check_output_path(src, tmp_path / "." / "r.csv")
    check_output_path(src, tmp_path / "out.csv")  # a different file is fine


def test_written_files_follow_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        out = tmp_path / "w.csv"
        write_recording(out, parse_recording(f"{HEADER}\n{GOOD}\n", "r.csv"))
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o644


def test_a_megabyte_cell_is_one_line_error() -> None:
    text = f"{HEADER}\n{GOOD}\n{_row(ax='1' * 1_000_000)}\n"
    with pytest.raises(RecordingError) as err:
        parse_recording(text, "r.csv")
    assert err.value.line == 3
    assert len(str(err.value)) < 300


@pytest.mark.parametrize("command", ["calibrate", "compensate", "import"])
def test_cli_refuses_an_output_that_is_its_input(
    tmp_path: Path, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from service.cli import main

    src = tmp_path / "r.csv"
    src.write_text(f"{HEADER}\n{GOOD}\n")
    before = src.read_bytes()
    argv = {
        "calibrate": ["calibrate", str(src), "-o", str(src)],
        "compensate": ["compensate", str(tmp_path / "m.json"), str(src), "-o", str(src)],
        "import": ["import", "--format", "imu_tk", str(src), "-o", str(tmp_path / "." / "r.csv")],
    }[command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "overwrite the input" in err and err.count("\n") == 1
    assert src.read_bytes() == before
