"""The plain-CSV reader (``recording._parse_plain``) agrees with the row-by-row reader.

Issue 10: the row-by-row reader held ~3.3 kB per reading; plain files are now read in C.
It must accept exactly what the row reader accepts, with the same numbers bit for bit,
the same raw cells, and leave every rejection (and its line and column) to the row reader.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import RecordingError
from calibration.recording import (
    DEFAULT_RANGE_G,
    TextRows,
    _parse_plain,
    _parse_rows,
    parse_recording,
)

HEADER = "t_s,step,chamber_c,position,ref_x,ref_y,ref_z,ax,ay,az,n,sd_x,sd_y,sd_z,label"


def _rows(n: int, rng: np.random.Generator) -> list[list[str]]:
    out = []
    for i in range(n):
        ax, ay, az = rng.normal(0.0, 0.6, 3)
        out.append(
            [
                repr(float(i) * 15.2),
                str(i // 8),
                f"{rng.uniform(-40, 60):.3f}",
                str(i % 8),
                "0.0",
                "0.0",
                "1.0",
                repr(float(ax)),
                f"{ay:.9e}",
                f"{az:+.12f}",
                "200",
                f"{abs(rng.normal(1e-4, 1e-5)):.6g}",
                "0.0001",
                ".0001",
                f"tag{i % 3}",
            ]
        )
    return out


def _text(rows: list[list[str]], header: str = HEADER, eol: str = "\n") -> str:
    return eol.join([header] + [",".join(r) for r in rows]) + eol


def _outcome(text: str) -> tuple[str, object]:
    try:
        rec = _parse_rows(text.lstrip("\ufeff"), "r.csv", range_g=DEFAULT_RANGE_G)
    except RecordingError as exc:
        return "error", str(exc)
    return "ok", rec


def _assert_same(text: str) -> None:
    """parse_recording (plain reader where it applies) == the row reader alone."""
    kind, want = _outcome(text)
    if kind == "error":
        with pytest.raises(RecordingError) as err:
            parse_recording(text, "r.csv")
        assert str(err.value) == want
        return
    got = parse_recording(text, "r.csv")
    assert got.header == want.header
    assert got.columns.keys() == want.columns.keys()
    for name, col in want.columns.items():
        assert got.columns[name].tobytes() == col.tobytes(), name  # NaN and -0.0 included
    assert list(got.cells) == list(want.cells)
    assert len(got.cells) == len(want.cells)


def test_plain_file_takes_the_plain_reader_and_matches() -> None:
    rng = np.random.default_rng(1)
    text = _text(_rows(50, rng))
    rec = _parse_plain(text, "r.csv")
    assert rec is not None and isinstance(rec.cells, TextRows)
    _assert_same(text)
    _assert_same(_text(_rows(50, rng), eol="\r\n"))  # CRLF, as from a Windows logger
    assert parse_recording(text).cells[3] == text.splitlines()[4].split(",")


def test_empty_cells_are_nan_in_both() -> None:
    rows = _rows(12, np.random.default_rng(2))
    rows[0][11] = rows[0][12] = rows[0][13] = ""  # sd not recorded
    rows[3][0 + 2] = ""  # a chamber_c gap: rejected by both, same line
    rows[5][-1] = ""  # last cell empty
    _assert_same(_text(rows[:3]))
    _assert_same(_text(rows))
    rows2 = [r[:] for r in rows[:3]]
    rows2[1][14] = ""
    _assert_same(_text(rows2))


@pytest.mark.parametrize("seed", range(40))
def test_random_damage_is_read_or_refused_the_same(seed: int) -> None:
    """Random edits the contract allows or forbids: both readers agree on every one."""
    rng = np.random.default_rng(seed)
    rows = _rows(int(rng.integers(1, 30)), rng)
    damage = [
        "",
        " ",
        "\t",
        '"',
        "nan",
        "inf",
        "1_0",
        "\u0661",
        "1e5",
        "+.5",
        "-0",
        "1.",
        "x",
        "\u00a0",
        "9" * 70,
        "1e-400",
        "1e400",
        "0x10",
        "\u2028",
        "  1",
        "-",
        ".",
    ]
    for _ in range(int(rng.integers(0, 4))):
        i, j = int(rng.integers(len(rows))), int(rng.integers(len(rows[0])))
        rows[i][j] = str(rng.choice(damage))
    text = _text(rows)
    edit = int(rng.integers(6))
    if edit == 1:  # a blank line somewhere, or only at the end
        lines = text.split("\n")
        lines.insert(int(rng.integers(1, len(lines) + 1)), "")
        text = "\n".join(lines)
    elif edit == 2:
        text = text.rstrip("\n")  # no final newline
    elif edit == 3:
        text += "\n\n,,,,,,,,,,,,,,\n"  # all-empty row at the end
    elif edit == 4:
        text = "\ufeff" + text.replace("\n", "\r\n", 2)  # BOM, mixed line ends
    elif edit == 5:
        text = text.replace(",", ",,", 1)  # one row a cell too long
    _assert_same(text)


def test_declines_what_it_does_not_check() -> None:
    rows = _rows(3, np.random.default_rng(3))
    good = _text(rows)
    assert _parse_plain(good, "r.csv") is not None
    for bad in (
        good.replace("tag0", '"tag,0"'),
        good.replace("\n", "\n\n", 2),
        good.replace("200", " 200", 1),
        good.replace("\n", "\r", 1),
        good.replace("200", "2" * 65, 1),
        good.replace("t_s", "t_s "),
        good.replace("200", "1e999", 1),
    ):
        assert _parse_plain(bad, "r.csv") is None


def test_text_cell_over_the_csv_limit_is_refused_as_before() -> None:
    import csv

    rows = _rows(2, np.random.default_rng(4))
    rows[1][14] = "t" * (csv.field_size_limit() + 1)
    _assert_same(_text(rows))
    rows[1][14] = "t" * 500  # long text is fine for both
    _assert_same(_text(rows))
