"""Recording format v1 (``docs/recording.md``): read, validate, write.

A :class:`Recording` keeps every column as a float array (NaN = empty cell)
plus the raw text cells, so commands that copy rows through (``compensate``)
keep unknown columns and formatting exactly. Every rejection names the file,
the 1-based line and the column.
"""

from __future__ import annotations

import csv
import functools
import io
import math
import os
import re
import stat
import tempfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import overload

import numpy as np

from calibration.errors import RecordingError

REQUIRED = ("t_s", "ax", "ay", "az")
TEMPERATURE = ("sensor_c", "chamber_c")
# Project addition: the table's commanded pose of each reading, a unit quaternion (scalar
# first) of the rotation from sensor to lab (docs/recording.md; calibration/table_pose.py)
POSE_COLUMNS: tuple[str, ...] = ("pose_qw", "pose_qx", "pose_qy", "pose_qz")
NUMERIC = (
    "t_s",
    "ax",
    "ay",
    "az",
    "chamber_c",
    "sensor_c",
    "ref_x",
    "ref_y",
    "ref_z",
    "step",
    "setpoint_c",
    "position",
    "n",
    "sd_x",
    "sd_y",
    "sd_z",
    "visit",  # project addition: the row's visit index within its step (docs/recording.md)
    # parsed as numbers, so a file that has them keeps no text for them (issue 22, memory)
    *POSE_COLUMNS,
)
# Order used when soakcal writes a recording (readers accept any order).
CANONICAL_ORDER = (
    "t_s",
    "step",
    "setpoint_c",
    "chamber_c",
    "sensor_c",
    "position",
    "visit",
    "ref_x",
    "ref_y",
    "ref_z",
    *POSE_COLUMNS,
    "ax",
    "ay",
    "az",
    "n",
    "sd_x",
    "sd_y",
    "sd_z",
)
DEFAULT_RANGE_G = 8.0  # ADXL355's widest range; a reading beyond it cannot be real
# A `_c` column outside this band is not a chamber or die temperature in °C (kelvin, or
# Fahrenheit, or a glitch): refused rather than fitted into a model "valid for 232..333 °C".
PLAUSIBLE_C = (-100.0, 200.0)
# A reference vector is the local specific force in g: 1.0 ± a few percent anywhere on Earth.
# Outside this band the column is in another unit (m/s², counts) and would move the bias by g.
PLAUSIBLE_REF_NORM_G = (0.5, 2.0)
# |t_s| beyond this is not seconds of a recording (10¹⁰ s: over 300 years; Unix time is
# 1.8·10⁹ s, the same in milliseconds 1.8·10¹²).
MAX_ABS_T_S = 1e10
MAX_CELL_CHARS = 64  # the longest honest number is ~25 characters
MAX_FILE_BYTES = 2 * 1024**3  # a recording bigger than this is not a recording
# Plain decimal numbers only: float() also takes "1_6384", "nan", "inf" and non-ASCII digits.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)


@dataclass
class Recording:
    """Columns of a v1 recording. ``columns[name]`` is a float array (NaN = not recorded)."""

    columns: dict[str, np.ndarray]
    header: list[str]
    path: str = "<memory>"
    # raw text rows, for copy-through: a list, or the plain reader's TextRows
    cells: Sequence[list[str]] | None = None
    notes: list[str] = field(default_factory=list)  # conditioning applied, said in reports

    # --- construction -------------------------------------------------
    @classmethod
    def from_columns(
        cls, columns: Mapping[str, Iterable[float]], path: str = "<memory>"
    ) -> Recording:
        cols = {
            k: np.asarray(list(v) if not isinstance(v, np.ndarray) else v, dtype=float)
            for k, v in columns.items()
        }
        header = [c for c in CANONICAL_ORDER if c in cols] + [
            c for c in cols if c not in CANONICAL_ORDER
        ]
        rec = cls(columns=cols, header=header, path=path)
        validate(rec)
        return rec

    # --- access ---------------------------------------------------------
    def __len__(self) -> int:
        return len(self.columns["t_s"])

    def has(self, name: str) -> bool:
        """Column present and at least one cell filled."""
        col = self.columns.get(name)
        return col is not None and bool(np.any(np.isfinite(col)))

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    @property
    def raw_g(self) -> np.ndarray:
        return np.column_stack([self.columns[c] for c in ("ax", "ay", "az")])

    @property
    def has_reference(self) -> bool:
        return all(self.has(c) for c in ("ref_x", "ref_y", "ref_z"))

    @property
    def ref_g(self) -> np.ndarray | None:
        if not self.has_reference:
            return None
        return np.column_stack([self.columns[c] for c in ("ref_x", "ref_y", "ref_z")])

    @property
    def sigma_g(self) -> np.ndarray | None:
        """Standard error of each averaged reading, sd/√n (g), where recorded."""
        if not all(self.has(c) for c in ("sd_x", "sd_y", "sd_z")):
            return None
        sd = np.column_stack([self.columns[c] for c in ("sd_x", "sd_y", "sd_z")])
        n = self.columns.get("n")
        if n is None or not np.any(np.isfinite(n)):
            return sd
        n = np.where(np.isfinite(n) & (n > 0), n, 1.0)
        return sd / np.sqrt(n)[:, None]

    @property
    def has_temperature(self) -> bool:
        return self.has("sensor_c") or self.has("chamber_c")

    @property
    def temperature_source(self) -> str:
        return "sensor_c" if self.has("sensor_c") else "chamber_c"

    def temperature_c(self) -> np.ndarray:
        """Thermal-model temperature: ``sensor_c`` where filled, else ``chamber_c`` (spec rule)."""
        # (a recording left with no rows keeps its sensor_c column, and nothing to fill)
        if self.has("sensor_c") or "chamber_c" not in self.columns:
            t = self.columns["sensor_c"].copy()
            if "chamber_c" in self.columns:
                gaps = ~np.isfinite(t)
                t[gaps] = self.columns["chamber_c"][gaps]
            return t
        return self.columns["chamber_c"].copy()

    def steps(self) -> np.ndarray:
        """Step index per row: ``step`` column, else setpoint changes, else temperature plateaus."""
        if self.has("step"):
            return np.nan_to_num(self.columns["step"], nan=-1).astype(int)
        if self.has("setpoint_c"):
            return _runs(self.columns["setpoint_c"], tol=1e-9)
        return _plateaus(self.temperature_c())

    def positions(self) -> np.ndarray:
        if self.has("position"):
            return np.nan_to_num(self.columns["position"], nan=-1).astype(int)
        steps = self.steps()
        pos = np.zeros(len(self), int)
        for s in np.unique(steps):
            idx = np.flatnonzero(steps == s)
            pos[idx] = np.arange(idx.size)
        return pos

    def subset(self, mask: np.ndarray) -> Recording:
        cols = {k: v[mask] for k, v in self.columns.items()}
        cells = None
        if self.cells is not None:
            cells = [row for row, keep in zip(self.cells, mask, strict=True) if keep]
        return Recording(cols, list(self.header), self.path, cells, list(self.notes))


# --- reading --------------------------------------------------------------
def read_recording(
    path: str | os.PathLike, *, range_g: float = DEFAULT_RANGE_G, raw_cells: bool = True
) -> Recording:
    """Read and validate a v1 CSV. Raises :class:`RecordingError` naming file, line, column.

    ``raw_cells=False``: the caller never copies rows through (``calibrate``, ``diagnose``),
    so a file of numeric columns only does not keep its text (:attr:`Recording.cells` is
    None): the text is as large as the file, 195 MB of a 2.4 M-row log held through the
    whole fit (issue 20). A text column (``ref_tol_deg``) is read from the cells, which are
    then kept.
    """
    p = Path(path)
    try:
        mode = p.stat().st_mode
        if stat.S_ISDIR(mode):
            raise RecordingError(str(p), None, None, "is a directory, not a recording file")
        if not stat.S_ISREG(mode):
            # /dev/zero or a FIFO would be read forever
            raise RecordingError(str(p), None, None, "is not a regular file")
        if p.stat().st_size > MAX_FILE_BYTES:
            raise RecordingError(
                str(p), None, None, f"is larger than {MAX_FILE_BYTES // 1024**3} GiB"
            )
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RecordingError(str(p), None, None, "file not found") from None
    except PermissionError:
        raise RecordingError(str(p), None, None, "permission denied") from None
    except UnicodeDecodeError as exc:
        raise RecordingError(str(p), None, None, f"not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise RecordingError(str(p), None, None, f"cannot be read ({exc.strerror})") from None
    return parse_recording(text, str(p), range_g=range_g, raw_cells=raw_cells)


def parse_recording(
    text: str, path: str = "<memory>", *, range_g: float = DEFAULT_RANGE_G,
    raw_cells: bool = True,
) -> Recording:
    """Parse and validate a v1 CSV text (see :func:`read_recording`).

    Plain files (no quotes, no spaces in cells, no blank lines but at the end: what
    soakcal and most loggers write) are read in C by :func:`_parse_plain`; anything
    else, and every file that would be rejected, goes through the row-by-row reader
    below, which names the line and column. Both give the same columns, bit for bit.
    """
    text = text.lstrip("\ufeff")
    rec = _parse_plain(text, path)
    if rec is not None:
        validate(rec, range_g=range_g, first_line=2)
    else:
        rec = _parse_rows(text, path, range_g=range_g)
    if not raw_cells and all(h in NUMERIC for h in rec.header):
        rec.cells = None  # every value is in ``columns``; nobody will copy a row through
    return rec


def _parse_rows(text: str, path: str, *, range_g: float) -> Recording:
    """Row-by-row reader: any CSV the contract allows, and the exact error for the rest."""
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise RecordingError(path, 1, None, "empty file: expected a header row") from None
    for name in REQUIRED:
        if name not in header:
            raise RecordingError(path, 1, name, _missing_column_message(header))
    if not any(t in header for t in TEMPERATURE):
        raise RecordingError(path, 1, "chamber_c", "needs a chamber_c or sensor_c column")
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise RecordingError(path, 1, sorted(dup)[0], "column appears twice in the header")
    numeric_idx = [(i, h) for i, h in enumerate(header) if h in NUMERIC]
    values: dict[str, list[float]] = {h: [] for _, h in numeric_idx}
    cells: list[list[str]] = []
    for line_no, row in _rows(reader, path):
        if not row or all(not c.strip() for c in row):
            continue  # blank line: tolerated (trailing newline)
        if len(row) != len(header):
            raise RecordingError(
                path, line_no, None, f"has {len(row)} cells, header has {len(header)}"
            )
        for i, h in numeric_idx:
            cell = row[i].strip()
            if cell == "":
                values[h].append(math.nan)
                continue
            if len(cell) > MAX_CELL_CHARS or not _NUMBER.fullmatch(cell):
                shown = cell if len(cell) <= 24 else cell[:24] + "…"
                raise RecordingError(path, line_no, h, f"not a number: {shown!r}")
            v = float(cell)
            if not math.isfinite(v):
                raise RecordingError(path, line_no, h, f"not a finite number: {cell!r}")
            values[h].append(v)
        cells.append(row)
    if not cells:
        raise RecordingError(path, 2, None, "no data rows after the header")
    cols = {h: np.asarray(v, dtype=float) for h, v in values.items()}
    rec = Recording(columns=cols, header=header, path=path, cells=cells)
    validate(rec, range_g=range_g, first_line=2)
    return rec


def _parse_plain(text: str, path: str) -> Recording | None:
    """The columns of a plain CSV, or None when the row-by-row reader must decide.

    Why: the row-by-row reader keeps a Python float and a Python string per cell
    (~3.3 kB per reading with io.StringIO's 4-byte copy of the text): 3.3 GB and a
    minute for a 1 M-row recording (issue 10). Here one regular expression checks every
    row at once against the rules :func:`_parse_rows` applies (cell count, plain ASCII
    decimal numbers of at most :data:`MAX_CELL_CHARS` characters), or, for a header of
    numeric columns only, :func:`_numeric_cells` checks them a block at a time (issue
    20: the expression took 4.5 s of 2.4 M rows), then numpy's C reader converts the
    numeric columns (``np.loadtxt``: the same correctly rounded
    conversion as ``float``). The text is kept once, for the raw cells of
    copy-through (:class:`TextRows`), instead of one string per cell.

    Declines (None) on anything it does not check itself: quotes, a lone CR, NUL,
    whitespace in a cell, a blank or all-empty row before the last data row, a header
    the row reader would strip or refuse, a number that overflows to infinity;
    :func:`_parse_rows` then reads the file and gives the same result or the error.
    """
    if '"' in text or "\x00" in text:
        return None
    if "\r" in text:
        if text.count("\r") != text.count("\r\n"):
            return None
        text = text.replace("\r\n", "\n")
    # The data rows are text[start:end], searched in place (pos/endpos), not copied.
    start = text.find("\n") + 1
    end = len(text)
    while end > start and text[end - 1] == "\n":  # not text.rstrip(): a copy of it all
        end -= 1
    if start == 0 or end <= start:
        return None
    header = text[: start - 1].split(",")
    if [h.strip() for h in header] != header or len(set(header)) != len(header):
        return None
    if any(name not in header for name in REQUIRED) or not any(t in header for t in TEMPERATURE):
        return None
    numeric = [i for i, h in enumerate(header) if h in NUMERIC]
    if len(numeric) == len(header) and text.isascii():
        # Numbers only (what soakcal writes): the rules below checked in C a block at a
        # time, 12 s less for 2.4 M rows (issue 20); the number syntax is numpy's.
        empty_cells = _numeric_cells(text, start, end, len(header))
        if empty_cells is None:
            return None
    else:
        empty_cells = _plain_cells(text, start, end, header)
        if empty_cells is None:
            return None

    # One block of text at a time into the columns, preallocated: a whole-file parse held
    # the table twice (rows-first, then columns-first), 230 MB of a 2.4 M-row log beside
    # its text (issue 20). The same C conversion, so the same numbers.
    n_rows = text.count("\n", start, end) + 1
    columns_first = np.empty((len(numeric), n_rows))
    row = 0
    try:
        for block in _blocks(text, start, end):
            if empty_cells:  # "not recorded" → NaN, which the row reader also gives
                block = _fill_empty(block)
            part = np.loadtxt(block.split("\n"), delimiter=",", dtype=float, comments=None,
                              usecols=numeric, ndmin=2)
            if row + part.shape[0] > n_rows:
                return None
            columns_first[:, row:row + part.shape[0]] = part.T
            row += part.shape[0]
    except ValueError:
        return None  # a cell of digits, signs, dots and e's that is not a number: "1e", "+-1"
    if row != n_rows:
        return None  # a row numpy skipped: the row reader decides
    if np.isinf(columns_first).any():
        return None  # "1e999": the row reader names its line and column
    cols = {header[i]: columns_first[j] for j, i in enumerate(numeric)}
    return Recording(columns=cols, header=header, path=path, cells=TextRows(text, start, end))


_SPACE = re.compile(r"[^\S\n]")  # any whitespace but the row separator (str.strip's set)
# The characters of the cells of a plain all-numeric recording, and its separators.
_NUMERIC_BYTES = b"0123456789+-.eE,\n"
_LINE = re.compile(r"[^\n]+")
BLOCK_CHARS = 1 << 20  # text handled at a time by the plain reader's checks and parser


def _blocks(text: str, start: int, end: int) -> Iterator[str]:
    """``text[start:end]`` in pieces of about :data:`BLOCK_CHARS`, cut at line ends (each
    piece without its final line feed)."""
    pos = start
    while pos < end:
        cut = text.find("\n", min(pos + BLOCK_CHARS, end), end)
        cut = end if cut < 0 else cut
        yield text[pos:cut]
        pos = cut + 1


def _fill_empty(block: str) -> str:
    """Each empty cell of the rows of ``block`` written ``nan``: what the line-by-line
    rule (a leading, a trailing, then every inner empty cell) gives for each row."""
    b = ("\n" + block + "\n").replace("\n,", "\nnan,").replace(",\n", ",nan\n")
    while ",," in b:
        b = b.replace(",,", ",nan,")
    return b[1:-1]


def _plain_cells(text: str, start: int, end: int, header: list[str]) -> bool | None:
    """Whether the rows ``text[start:end]`` have an empty cell, or ``None`` when they are
    not all plain (:func:`_parse_plain`): a blank row, whitespace the row reader strips,
    an all-empty row (the row reader skips it, loadtxt would not), a cell
    :func:`_plain_rows` does not match."""
    if text.find("\n\n", start, end) >= 0 or _SPACE.search(text, start, end):
        return None
    empty_row = "\n" + "," * (len(header) - 1)
    if text.startswith(empty_row[1:] + "\n", start) or text[start:end] == empty_row[1:]:
        return None
    i = text.find(empty_row, start, end)
    while i >= 0:
        if i + len(empty_row) >= end or text[i + len(empty_row)] == "\n":
            return None
        i = text.find(empty_row, i + 1, end)
    rows = _plain_rows(tuple(h in NUMERIC for h in header), csv.field_size_limit())
    if rows.fullmatch(text, start, end) is None:
        return None
    return (
        text.startswith(",", start)
        or text.endswith(",", start, end)
        or any(text.find(p, start, end) >= 0 for p in (",,", "\n,", ",\n"))
    )


def _numeric_cells(text: str, start: int, end: int, n_cells: int) -> bool | None:
    """:func:`_plain_cells` for a header of numeric columns only and ASCII text.

    Every row of ``text[start:end]`` must be ``n_cells`` cells, each empty or at most
    :data:`MAX_CELL_CHARS` of the characters ``0-9 + - . e E`` (no whitespace, so no
    blank row), and not all empty. Which digit strings are numbers is left to
    ``np.loadtxt``: over these characters it accepts exactly :data:`_NUMBER`."""
    empty = False
    for block in _blocks(text, start, end):
        raw = block.encode("ascii") + b"\n"
        if raw.translate(None, _NUMERIC_BYTES):
            return None
        chars = np.frombuffer(raw, np.uint8)
        seps = np.flatnonzero((chars == ord(",")) | (chars == ord("\n")))
        widths = np.diff(seps, prepend=-1) - 1
        if int(widths.max()) > MAX_CELL_CHARS:
            return None
        ends = np.flatnonzero(chars[seps] == ord("\n"))
        if (np.diff(ends, prepend=-1) != n_cells).any():
            return None
        if int(widths.min()) == 0:
            empty = True
            # an all-empty row: n_cells - 1 commas and nothing else
            if (np.diff(seps[ends], prepend=-1) == n_cells).any():
                return None
    return empty


@functools.lru_cache(maxsize=16)
def _plain_rows(numeric: tuple[bool, ...], text_chars: int) -> re.Pattern[str]:
    """Rows of plain cells: numbers (or empty) in numeric columns, text elsewhere.

    A number is :data:`_NUMBER` (ASCII digits) of at most :data:`MAX_CELL_CHARS`
    characters; a text cell at most ``text_chars`` (the csv module's field limit).
    Atomic groups: a cell or row once matched is never re-split (without them a
    failing row made the engine retry every way of cutting the digits before it).
    """
    number = f"(?=[^,\\n]{{0,{MAX_CELL_CHARS}}}+(?![^,\\n]))(?>{_NUMBER.pattern})"
    text = f"[^,\\n]{{0,{text_chars}}}+"
    row = ",".join(f"(?:{number})?" if is_num else text for is_num in numeric)
    return re.compile(f"(?>{row}\\n)*+{row}", re.ASCII)


class TextRows(Sequence[list[str]]):
    """The raw cells of a plain CSV's data rows, split on demand from its text.

    What :func:`_parse_rows` keeps as a list of lists (one str per cell, ~1.3 kB per
    row), held as the one text: only copy-through (``compensate``) and text columns
    (``ref_tol_deg``) read it. ``text[start:end]`` are the rows, one per line.
    """

    def __init__(self, text: str, start: int, end: int) -> None:
        self._text, self._start, self._end = text, start, end
        self._len = text.count("\n", start, end) + 1
        self._rows: list[list[str]] | None = None

    def __len__(self) -> int:
        return self._len

    def __iter__(self) -> Iterator[list[str]]:
        if self._rows is not None:
            yield from self._rows
            return
        for m in _LINE.finditer(self._text, self._start, self._end):
            yield m.group().split(",")

    @overload
    def __getitem__(self, i: int) -> list[str]: ...
    @overload
    def __getitem__(self, i: slice) -> list[list[str]]: ...
    def __getitem__(self, i: int | slice) -> list[str] | list[list[str]]:
        if self._rows is None:  # random access is rare: materialise once
            self._rows = list(self)
        return self._rows[i]


def validate(rec: Recording, *, range_g: float = DEFAULT_RANGE_G, first_line: int = 2) -> None:
    """Spec rules: required values present, t_s non-decreasing, readings within range."""
    path = rec.path
    n = len(rec.columns["t_s"])
    for name in REQUIRED:
        col = rec.columns[name]
        if len(col) != n:
            raise RecordingError(path, None, name, f"has {len(col)} values, t_s has {n}")
        missing = np.flatnonzero(~np.isfinite(col))
        if missing.size:
            line = first_line + int(missing[0])
            raise RecordingError(path, line, name, "required value is empty")
    back = np.flatnonzero(np.diff(rec.columns["t_s"]) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise RecordingError(
            path,
            first_line + i,
            "t_s",
            f"time goes backwards ({rec.columns['t_s'][i]} after {rec.columns['t_s'][i - 1]})",
        )
    for name in ("ax", "ay", "az"):
        over = np.flatnonzero(np.abs(rec.columns[name]) > range_g)
        if over.size:
            i = int(over[0])
            raise RecordingError(
                path,
                first_line + i,
                name,
                f"reading {rec.columns[name][i]} g is outside the sensor range ±{range_g} g",
            )
    _validate_plausible(rec, first_line, range_g)
    if not any(t in rec.columns for t in TEMPERATURE):
        raise RecordingError(path, None, "chamber_c", "needs a chamber_c or sensor_c column")
    temp = rec.temperature_c()
    empty = np.flatnonzero(~np.isfinite(temp))
    # A recording with no temperature at all (imports from labs without a temperature
    # channel) is one step at an unknown temperature; a gap in an otherwise
    # temperature-bearing recording is an error.
    if empty.size and empty.size < temp.size:
        raise RecordingError(
            path,
            first_line + int(empty[0]),
            rec.temperature_source,
            "no temperature in this row (neither sensor_c nor chamber_c)",
        )


def _rows(reader: Iterable[list[str]], path: str) -> Iterable[tuple[int, list[str]]]:
    """Data rows with their 1-based line numbers; csv's own errors (a cell over its field
    limit, a NUL byte) become a RecordingError on that line."""
    it = iter(reader)
    line_no = 1
    while True:
        line_no += 1
        try:
            row = next(it)
        except StopIteration:
            return
        except csv.Error as exc:
            reason = "a cell is too long" if "field larger" in str(exc) else str(exc)
            raise RecordingError(path, line_no, None, f"not valid CSV: {reason}") from None
        yield line_no, row


def _validate_plausible(rec: Recording, first_line: int,
                        range_g: float = DEFAULT_RANGE_G) -> None:
    """Values no real recording holds: kelvin in a `_c` column, n < 1, a negative sd or
    one beyond the sensor's range, a negative or fractional step/position/visit, a time
    beyond :data:`MAX_ABS_T_S`, a reference vector that is not ~1 g, and a reference
    given on some axes only."""
    path = rec.path

    def first_bad(name: str, bad: np.ndarray, message: str) -> None:
        idx = np.flatnonzero(bad)
        if idx.size:
            i = int(idx[0])
            value = rec.columns[name][i]
            raise RecordingError(path, first_line + i, name, message.format(value=value))

    lo, hi = PLAUSIBLE_C
    for name in [c for c in rec.columns if c.endswith("_c")]:
        col = rec.columns[name]
        first_bad(
            name,
            np.isfinite(col) & ((col < lo) | (col > hi)),
            f"{{value:g}} is not a plausible temperature in °C (expected {lo:g} .. {hi:g} °C;"
            " kelvin or °F? convert to °C)",
        )
    if "n" in rec.columns:
        n = rec.columns["n"]
        first_bad(
            "n",
            np.isfinite(n) & ((n < 1) | (n != np.round(n))),
            "n = {value:g}: the number of averaged samples must be a whole number ≥ 1",
        )
    for name in ("sd_x", "sd_y", "sd_z"):
        if name in rec.columns:
            sd = rec.columns[name]
            first_bad(
                name, np.isfinite(sd) & (sd < 0), "standard deviation {value:g} g is negative"
            )
            first_bad(
                name, np.isfinite(sd) & (sd > range_g),
                f"standard deviation {{value:g}} g is beyond the sensor's range ±{range_g:g} g: "
                "not a scatter of readings (sd_* are in g)")
    for name in ("step", "position", "visit"):
        if name in rec.columns:
            v = rec.columns[name]
            first_bad(
                name, np.isfinite(v) & ((v < 0) | (v != np.round(v))),
                f"{name} = {{value:g}}: a {name} index is a whole number ≥ 0 (leave the cell "
                "empty for a row outside any " + name + ")")
    t = rec.columns["t_s"]
    first_bad(
        "t_s", np.abs(t) > MAX_ABS_T_S,
        f"t_s = {{value:g}} s is not a time in seconds (more than {MAX_ABS_T_S:g} s, "
        "over 300 years; milliseconds? divide by 1000)")
    refs = [c for c in ("ref_x", "ref_y", "ref_z") if c in rec.columns]
    if refs:
        filled = np.column_stack([np.isfinite(rec.columns[c]) for c in refs])
        partial = filled.any(axis=1) & ~filled.all(axis=1)
        if len(refs) < 3:
            partial = filled.any(axis=1)
        if partial.any():
            i = int(np.flatnonzero(partial)[0])
            gap = next(
                (
                    c
                    for c in ("ref_x", "ref_y", "ref_z")
                    if c not in rec.columns or not np.isfinite(rec.columns[c][i])
                ),
                "ref_x",
            )
            raise RecordingError(
                path,
                first_line + i,
                gap,
                "reference vector is incomplete: fill ref_x, ref_y and ref_z, or none of them",
            )
        if len(refs) == 3:
            ref = np.column_stack([rec.columns[c] for c in refs])
            norm = np.linalg.norm(ref, axis=1)
            rlo, rhi = PLAUSIBLE_REF_NORM_G
            bad = np.isfinite(norm) & ((norm < rlo) | (norm > rhi))
            idx = np.flatnonzero(bad)
            if idx.size:
                i = int(idx[0])
                raise RecordingError(
                    path,
                    first_line + i,
                    "ref_x",
                    f"reference vector magnitude {norm[i]:g} g is not local gravity "
                    f"(expected {rlo:g} .. {rhi:g} g; ref_* are in g, not m/s² or counts)",
                )


def _missing_column_message(header: list[str]) -> str:
    """Name the missing column and hint at the likely cause (a separator other than ',')."""
    shown = ",".join(header)
    if len(shown) > 120:
        shown = shown[:120] + "…"
    message = f"required column missing (header: {shown})"
    if len(header) == 1:
        for sep, name in ((";", "semicolon"), ("\t", "tab"), ("|", "pipe")):
            if sep in header[0]:
                return message + f"; the file looks {name}-separated: recordings use commas"
    return message


def check_output_path(input_path: str | os.PathLike, output_path: str | os.PathLike) -> None:
    """Refuse an output that would overwrite an input (``-o`` equal to the recording)."""
    out = Path(output_path)
    try:
        same = out.exists() and os.path.samefile(input_path, out)
    except OSError:
        same = False
    if same:
        raise RecordingError(str(out), None, None, "output would overwrite the input file")
    if out.is_dir():
        raise RecordingError(str(out), None, None, "output is a directory; give a file name")


# --- writing --------------------------------------------------------------
def write_recording(
    path: str | os.PathLike, rec: Recording | Mapping[str, Iterable[float]]
) -> None:
    """Write a v1 CSV atomically (temp file + rename): a crash never leaves half a file."""
    if not isinstance(rec, Recording):
        rec = Recording.from_columns(rec)
    header = rec.header
    chunks = _csv_chunks(header, [rec.columns[h] for h in header])
    if chunks is None:  # columns the column-wise writer does not take: row by row
        rows = zip(*(rec.columns[h] for h in header), strict=True)
        chunks = iter([_csv_text(header, rows)])
    atomic_write_text(path, chunks)


def recording_text(rec: Recording) -> str:
    chunks = _csv_chunks(rec.header, [rec.columns[h] for h in rec.header])
    if chunks is not None:
        return "".join(chunks)
    return _csv_text(rec.header, zip(*(rec.columns[h] for h in rec.header), strict=True))


def atomic_write_text(path: str | os.PathLike, text: str | Iterator[str]) -> None:
    """Write ``text`` (or its pieces, written one after the other) atomically: a temp
    file beside ``path``, renamed over it once complete."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", dir=p.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            if isinstance(text, str):
                fh.write(text)
            else:
                for piece in text:
                    fh.write(piece)
        # mkstemp creates 0600; an output file follows the umask like any other
        os.chmod(tmp, 0o666 & ~_current_umask())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _current_umask() -> int:
    """The process umask, read without changing it where the OS allows (threads may write)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def format_value(v: float, name: str = "") -> str:
    if not math.isfinite(v):
        return ""
    if name in ("step", "position", "visit", "n") and float(v).is_integer():
        return str(int(v))
    return repr(float(v))


def _csv_text(header: list[str], rows: Iterable[Iterable[float]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([format_value(v, h) for v, h in zip(row, header, strict=True)])
    return buf.getvalue()


# Columns written as whole numbers when they hold one (:func:`format_value`).
_WHOLE_COLUMNS = ("step", "position", "visit", "n")
# Rows formatted at a time by the column-wise writer: a bounded number of cell strings.
WRITE_CHUNK_ROWS = 1 << 16


def _csv_chunks(header: list[str], columns: Sequence[object]) -> Iterator[str] | None:
    """The CSV text of :func:`_csv_text`, character for character, a block of rows at a
    time, or ``None`` for columns it does not take (anything but 1-D numeric arrays of
    one length, at most 64-bit: those go row by row).

    Why (issue 20): one :func:`format_value` call and one csv row per cell cost 25 s for
    a 2.4 M-row log. Here each column is formatted at once by the same functions
    (``repr`` of each Python float, ``str`` of each whole number): the cells are the
    same strings, and none needs the csv module's quoting (digits, ``.``, ``e``, ``+``,
    ``-``, or empty) when a row has more than one cell.
    """
    arrays = [c for c in columns if isinstance(c, np.ndarray)]
    if (
        len(header) < 2
        or len(arrays) != len(header)
        or any(a.ndim != 1 or a.dtype.kind not in "fiub" or a.dtype.itemsize > 8
               for a in arrays)
        or len({a.shape[0] for a in arrays}) != 1
    ):
        return None
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(header)

    def chunks() -> Iterator[str]:
        yield buf.getvalue()
        n, k = arrays[0].shape[0], len(arrays)
        for lo in range(0, n, WRITE_CHUNK_ROWS):
            rows = min(WRITE_CHUNK_ROWS, n - lo)
            # cell, ",", cell, ",", …, cell, "\n" for each row, joined once
            pieces = [","] * (2 * k * rows)
            pieces[2 * k - 1::2 * k] = ["\n"] * rows
            for j, (a, h) in enumerate(zip(arrays, header, strict=True)):
                pieces[2 * j::2 * k] = _format_column(a[lo:lo + rows], h)
            yield "".join(pieces)

    return chunks()


def _format_column(col: np.ndarray, name: str) -> list[str]:
    """:func:`format_value` of every cell of a numeric column, as one list."""
    if name in _WHOLE_COLUMNS and col.dtype.kind in "iu":
        return list(map(str, col.tolist()))  # exact integers, as int(v) of each
    x = col.astype(np.float64)
    bits = x.view(np.int64)
    if x.size and (bits == bits[0]).all():  # n = 1, an empty temperature: one cell, repeated
        return [format_value(x[0], name)] * x.size
    finite = np.isfinite(x)
    if not finite.any():
        return [""] * x.size
    if name in _WHOLE_COLUMNS:
        whole = finite & (x == np.trunc(x)) & (np.abs(x) < 2.0**63)
        if whole.all():
            return list(map(str, x.astype(np.int64).tolist()))
    out = list(map(repr, x.tolist()))
    if name in _WHOLE_COLUMNS:
        for i in np.flatnonzero(finite).tolist():
            out[i] = format_value(x[i], name)
    for i in np.flatnonzero(~finite).tolist():
        out[i] = ""
    return out


def _runs(values: np.ndarray, tol: float) -> np.ndarray:
    change = np.r_[False, np.abs(np.diff(np.nan_to_num(values))) > tol]
    return np.cumsum(change)


def _plateaus(temp_c: np.ndarray, jump_c: float = 2.0) -> np.ndarray:
    """Steps from temperature plateaus: a new step where T moves more than ``jump_c`` from
    the running mean of the current plateau."""
    steps = np.zeros(temp_c.size, int)
    start, k = 0, 0
    total = float(temp_c[0]) if temp_c.size else 0.0  # running sum of the plateau so far
    # a running sum, not np.mean of the slice: that was O(n²), minutes on 10⁵ raw rows
    values = temp_c.tolist()
    for i in range(1, len(values)):
        if abs(values[i] - total / (i - start)) > jump_c:
            k += 1
            start, total = i, 0.0
        total += values[i]
        steps[i] = k
    return steps


def optional_number_column(rec: Recording, name: str, unit: str) -> np.ndarray | None:
    """An optional numeric column the reader does not parse (``placement``'s ``ref_tol_deg``,
    ``temperature_lsb``'s ``*_lsb_c``) as floats, NaN where empty, from the parsed columns or
    the raw cells; None when absent. A cell that is not a finite number is an error naming
    the line and column (``unit``: what the number is of, for the message)."""
    if name in rec.columns:
        return np.asarray(rec.columns[name], float)
    if rec.cells is None or name not in rec.header:
        return None
    j = rec.header.index(name)
    out = np.full(len(rec.cells), math.nan)
    for i, row in enumerate(rec.cells):
        cell = row[j].strip() if j < len(row) else ""
        if not cell:
            continue
        try:
            out[i] = float(cell)
        except ValueError:
            raise RecordingError(rec.path, i + 2, name,
                                 f"{cell!r} is not a number of {unit}") from None
        if not math.isfinite(out[i]):
            raise RecordingError(rec.path, i + 2, name,
                                 f"{cell!r} is not a finite number of {unit}")
    return out
